//! The console's state and what each key does. Drawing is in [`crate::ui`]; the terminal loop
//! in `main.rs`. Everything here runs without a terminal, so the tests drive it directly.

use crate::form::{Action, Form};
use crate::rest::Rest;
use crate::results::{ChartsView, HistoryEntry, MoveResult};
use crate::starter_process::{Mode, Running};
use crate::tuning::{self, TuneEnded, TuneResult};
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime};

mod hints;
mod jog;
mod keys;

/// The console's pages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Page {
    /// The five sections of settings and the actions (F1).
    Setup,
    /// The starter's output (F3).
    Log,
    /// The last move's summary (F4).
    Results,
    /// The last move's charts (F7).
    Charts,
    /// The session's moves (F8).
    History,
}

/// How the console ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quit {
    /// Exit: the settings were saved.
    Saved,
    /// Cancel: the file was left as it was.
    Cancelled,
}

/// Lines of starter output kept.
pub const LOG_LINES: usize = 2_000;

/// How often the robot at rest is read again while no move runs (its state file may change,
/// and the settings with it).
const REST_EVERY: Duration = Duration::from_secs(2);

/// The console.
#[derive(Debug)]
pub struct App {
    /// The settings form.
    pub form: Form,
    /// The page shown.
    pub page: Page,
    /// The focused field.
    pub focus: usize,
    /// The focused field's text when editing began (Esc restores it).
    pub editing: Option<String>,
    /// The message line and whether it is an error.
    pub status: (String, bool),
    /// The status line holds a message of this key or of the last move: not replaced by the
    /// page's hint until the next key.
    said: bool,
    /// The starter's output.
    pub log: Vec<String>,
    /// How far the log page is scrolled up from its end, in screen rows (0: it follows the
    /// output as it comes).
    pub log_scroll: usize,
    /// How far the results and history pages are scrolled down from their top, in rows.
    pub page_scroll: usize,
    /// The iceoryx2 root of the moves (to clean up after a starter that had to be killed).
    pub iox_root: String,
    /// A move in progress.
    pub running: Option<Running>,
    /// The last move's outcome; when the last move left none of its own (refused before
    /// anything moved), the results an earlier move left in the output folder, which
    /// [`App::results_note`] then says.
    pub last: Option<MoveResult>,
    /// Why the results shown are not the last move's own (it left none: `last` holds the
    /// output folder's, an earlier move's), or why there are none (the folder's files cannot
    /// be read); `None` when `last` is the last move's, or when no move has written there.
    pub results_note: Option<String>,
    /// The robot at rest, as far as it is known (read again every two seconds while no
    /// move runs, and when one ends).
    pub rest: Rest,
    /// When `rest` was read.
    rest_read: Option<Instant>,
    /// The last tuning's outcome (Ctrl-T).
    pub tuned: Option<TuneResult>,
    /// The running move's live telemetry (the charts page while it runs).
    pub live: Option<crate::live::Live>,
    /// The session's moves.
    pub history: Vec<HistoryEntry>,
    /// The motor the charts show (0-based).
    pub chart_motor: usize,
    /// What the jog keys move: motor 1‥n, then n + 1‥n + 3 the effector along x, y, z.
    pub jog_motor: usize,
    /// "Go to X Y Z" being typed (Ctrl-G): its text.
    pub prompt: Option<String>,
    /// What the gripper was last told from here (Ctrl-O toggles it).
    pub grip_closed: bool,
    /// Set when the console should end.
    pub quit: Option<Quit>,
    /// `qmarc-starter`.
    pub starter: PathBuf,
    /// Options given to every starter run before `--config` (iceoryx2 prefix and root).
    pub starter_args: Vec<String>,
    /// Where moves run (relative settings paths are relative to it).
    pub workdir: PathBuf,
}

impl App {
    /// A console on `form`, running moves with `starter` in `workdir`.
    pub fn new(form: Form, starter: PathBuf, workdir: PathBuf) -> App {
        let mut app = App {
            form,
            page: Page::Setup,
            focus: 0,
            editing: None,
            status: (String::new(), false),
            said: false,
            log: Vec::new(),
            log_scroll: 0,
            page_scroll: 0,
            iox_root: qmarc_proto::service::DEFAULT_ROOT.to_string(),
            running: None,
            last: None,
            results_note: None,
            rest: Rest::unknown("not known yet"),
            rest_read: None,
            tuned: None,
            live: None,
            history: Vec::new(),
            chart_motor: 0,
            jog_motor: 1,
            prompt: None,
            grip_closed: false,
            quit: None,
            starter,
            starter_args: Vec::new(),
            workdir,
        };
        // The last move's results, if its files are there: shown, and its timing is what a
        // new servo period is checked against.
        let out = app.out_dir();
        match MoveResult::load(&out) {
            Ok(r) => {
                app.form.last_cycle_work_us = r.cycle_work_us();
                app.form.validate();
                app.last = Some(r);
            }
            Err(e) => app.results_note = crate::results::why_none(&out, &e),
        }
        app.refresh_rest();
        app.hint();
        app
    }

    /// Reads the robot at rest again ([`Rest::of`]): the settings as they check now, the
    /// starter's options and the last results.
    pub fn refresh_rest(&mut self) {
        self.rest = match &self.form.checked {
            Some(s) => Rest::of(
                s,
                &self.starter_args,
                &self.workdir,
                self.last.as_ref(),
                SystemTime::now(),
            ),
            None => Rest::unknown("not known: the settings do not validate"),
        };
        self.rest_read = Some(Instant::now());
    }

    /// What the charts page (F7) shows: the running move's live telemetry once it has
    /// samples; else the gathered data of the last move — or of an earlier one, said so, when
    /// the last left none of its own (a move refused before anything moved leaves the folder
    /// as it was); else why there is nothing to chart.
    pub fn charts_view(&self) -> ChartsView<'_> {
        if let Some(live) =
            self.live.as_ref().filter(|l| self.running.is_some() && !l.series.t.is_empty())
        {
            return ChartsView::Live(live);
        }
        let note = self.results_note.as_deref();
        let Some(last) = &self.last else {
            return ChartsView::Nothing(match note {
                Some(why) => format!("Nothing to chart: {why}"),
                None => format!(
                    "No gathered data yet: no move has written {}.",
                    self.out_dir().join("gather.csv").display()
                ),
            });
        };
        let whose = |what: &str| {
            let age = last.age(SystemTime::now()).map(|a| format!(", {a}")).unwrap_or_default();
            note.map(|why| {
                format!("{what} of an earlier move ({}{age}) — {why}", last.summary.what())
            })
        };
        match &last.series {
            Ok(series) => {
                ChartsView::Gathered { result: last, series, note: whose("The gathered data") }
            }
            Err(e) => {
                // A set without data keeps the last complete one in `previous/`.
                let previous = last.dir.join(qmarc_report::output::PREVIOUS_DIR);
                let kept = if previous.join("gather.csv").is_file() {
                    format!("; the last complete set is in {}", previous.display())
                } else {
                    String::new()
                };
                let what = whose("The results").map(|w| format!("{w}. ")).unwrap_or_default();
                ChartsView::Nothing(format!(
                    "{what}No gathered data to chart for the {} move: {e}{kept}",
                    last.summary.what()
                ))
            }
        }
    }

    pub(crate) fn say(&mut self, msg: impl Into<String>, error: bool) {
        self.status = (msg.into(), error);
        self.said = true;
    }

    /// The output directory of the settings as they stand.
    pub fn out_dir(&self) -> PathBuf {
        let out = self
            .form
            .fields
            .iter()
            .find(|f| f.label == "Out dir")
            .map_or_else(|| "out".to_string(), |f| f.text.clone());
        self.workdir.join(out)
    }

    /// Saves the settings and starts `mode` (thesis 3.4: a button saves, then spawns the
    /// starter), unless a field it needs does not validate.
    pub fn start(&mut self, mode: Mode) {
        if self.running.is_some() {
            return self.say("a move is running: F9 aborts it", true);
        }
        self.commit_edit();
        let action = match mode {
            Mode::Home => Action::Home,
            Mode::Run => Action::Run,
            Mode::Step => Action::Step,
            // It runs the path.
            Mode::Tune => Action::Run,
            // As homing: the settings, and no knot file.
            Mode::Jog { .. }
            | Mode::JogAxis { .. }
            | Mode::GoTo { .. }
            | Mode::Grip { .. }
            | Mode::Conveyor => Action::Home,
        };
        if let Some((field, e)) = self.form.blocking(action) {
            if let Some(i) = field {
                self.focus = i;
            }
            self.page = Page::Setup;
            return self.say(format!("cannot {}: {e}", mode.arg()), true);
        }
        if let Err(e) = self.form.save() {
            return self.say(e, true);
        }
        match Running::start(
            &self.starter,
            &self.starter_args,
            &self.form.path,
            mode,
            &self.workdir,
        ) {
            Ok(mut r) => {
                // What the move runs with, taken now: the form stays editable meanwhile.
                r.out_dir = self.out_dir();
                r.gains = self.gains();
                if mode != Mode::Tune {
                    let robot = self.form.checked.as_ref().and_then(|s| s.robot());
                    let live =
                        crate::live::Live::for_move(&self.starter_args, &self.iox_root, r.pid())
                            .with_robot(robot)
                            .with_belt(mode == Mode::Conveyor);
                    self.live = Some(live);
                }
                self.log.push(format!("── {} ──", mode.arg()));
                self.running = Some(r);
                self.page = Page::Log;
                self.say(format!("{} running · F9 aborts (motors disabled)", mode.arg()), false);
            }
            Err(e) => self.say(
                format!("cannot start {} ({}): {e}", mode.arg(), self.starter.display()),
                true,
            ),
        }
    }

    /// Stops the running move.
    pub fn abort(&mut self) {
        if let Some(r) = self.running.as_mut().filter(|r| r.aborted.is_none()) {
            r.abort();
            self.say(
                "aborting: the motors are being disabled… (F9 again after 5 s kills the starter)",
                true,
            );
        }
    }

    /// F9: aborts the move; pressed again more than 5 s after an abort that did not end it,
    /// kills the starter (its children stop on their parent-death signal).
    fn abort_key(&mut self) {
        match self.running.as_mut().and_then(|r| r.aborted.map(|at| (r, at))) {
            Some((r, at)) if at.elapsed() > std::time::Duration::from_secs(5) => {
                r.kill();
                self.say("qmarc-starter killed: its children stop on their own", true);
            }
            Some(_) => {}
            None => self.abort(),
        }
    }

    /// Aborts a running move and waits up to `timeout` for it to end (the console is
    /// closing). Err with the starter's pid if it is still running then.
    pub fn abort_and_wait(&mut self, timeout: std::time::Duration) -> Result<(), u32> {
        let start = std::time::Instant::now();
        self.abort();
        while self.running.is_some() && start.elapsed() < timeout {
            std::thread::sleep(std::time::Duration::from_millis(20));
            self.poll();
        }
        self.running.as_ref().map_or(Ok(()), |r| Err(r.pid()))
    }

    /// (Kp, Kd, Kvff) of the motors as the settings check now.
    fn gains(&self) -> Vec<(f64, f64, f64)> {
        self.form
            .checked
            .as_ref()
            .map(|c| c.motors.iter().take(c.n_motors).map(|g| (g.kp, g.kd, g.kvff)).collect())
            .unwrap_or_default()
    }

    /// Takes the starter's output; when the move has ended, loads its results.
    pub fn poll(&mut self) {
        if let Some(l) = &mut self.live {
            l.poll();
        }
        if self.running.is_none() && self.rest_read.is_none_or(|t| t.elapsed() > REST_EVERY) {
            self.refresh_rest();
        }
        let Some(r) = &mut self.running else { return };
        let mut fresh = r.drain();
        let ended = r.finished();
        if ended.is_some() {
            // Its last lines (why it failed, often) may still be on their way from the
            // children.
            fresh.extend(r.drain_to_end(std::time::Duration::from_secs(2)));
        }
        let tuning = r.mode == Mode::Tune;
        if tuning {
            self.tune_progress(&fresh);
        }
        self.log.extend(fresh);
        self.trim_log();
        let Some(status) = ended else { return };
        let Some(r) = self.running.take() else { return };
        self.live = None;
        if r.killed {
            // Its children stop on their parent-death signal; what it could not remove goes
            // now (or with the next run) — only prefixes no live process uses.
            std::thread::sleep(std::time::Duration::from_millis(200));
            qmarc_session::discovery::remove_stale_files(&self.iox_root);
        }
        if tuning {
            self.tune_ended(&r, status);
            return self.refresh_rest();
        }
        self.move_ended(&r, status);
        self.refresh_rest();
    }

    /// Puts the last of the tuning's progress lines among `lines` on the message line.
    fn tune_progress(&mut self, lines: &[String]) {
        if let Some(p) = tuning::progress(lines) {
            self.say(p, false);
        }
    }

    /// The tuning started by `r` ended with `status`: its summary and, where there is one,
    /// the path with the tuned gains as the last move.
    fn tune_ended(&mut self, r: &Running, status: std::process::ExitStatus) {
        match tuning::ended(&r.out_dir, r.pid(), status) {
            Err(why) => {
                // The results page must not show an earlier tuning as this one's.
                self.tuned = None;
                self.page = Page::Log;
                self.say(why, true);
            }
            Ok(TuneEnded { result, last, note, message }) => {
                self.last = last;
                self.results_note = note;
                self.tuned = Some(result);
                self.show(Page::Results);
                self.say(message.0, message.1);
            }
        }
    }

    /// Ctrl-A: the last tuning's gains (those it tuned) into the form. Not saved: F10 saves
    /// them, and the next move saves and runs with them.
    pub fn apply_tuned(&mut self) {
        if self.running.is_some() {
            return self.say("a move is running: its end comes first", true);
        }
        let Some(t) = &self.tuned else {
            return self.say("no tuning yet: Ctrl-T tunes the gains on the path", true);
        };
        let tuned = t.tuned_gains();
        self.commit_edit();
        let mut changed = 0;
        for (place, text) in tuned {
            if let Some(i) = self.form.index(place) {
                self.form.fields[i].text = text;
                changed += 1;
            }
        }
        self.form.validate();
        self.say(
            format!(
                "{changed} tuned gains in the form, not yet saved: F10 saves them, and the next \
                 move saves and runs with them"
            ),
            false,
        );
    }

    /// The move `r` ended with `status`: its results shown, or why there are none.
    fn move_ended(&mut self, r: &Running, status: std::process::ExitStatus) {
        match MoveResult::load_for(&r.out_dir, r.pid()) {
            Ok(result) => {
                if let (Mode::Grip { close }, None) = (r.mode, &result.summary.fault) {
                    self.grip_closed = close;
                }
                if let Some(t) = &mut self.tuned {
                    t.latest = false;
                }
                self.record(r.gains.clone(), &result);
                let fault = result
                    .summary
                    .fault
                    .as_ref()
                    .map(|f| format!("FAULT {}: {}", f.kind, f.message));
                self.form.last_cycle_work_us = result.cycle_work_us();
                // The period is checked again against what this move measured.
                self.form.validate();
                self.last = Some(result);
                self.results_note = None;
                self.show(Page::Results);
                self.page_scroll = 0;
                match fault {
                    Some(f) => self.say(f, true),
                    None => {
                        self.say(format!("{} done · F7 charts · F8 history", r.mode.arg()), false)
                    }
                }
            }
            Err(e) => {
                // The results pages must not show the move before as this one's: they show
                // what the output folder holds (a move refused before anything moved leaves
                // it as it was) as an earlier move's, and say why.
                let why =
                    format!("the last move ({}) left none of its own ({status})", r.mode.arg());
                match MoveResult::load(&r.out_dir) {
                    Ok(earlier) => {
                        self.last = Some(earlier);
                        self.results_note = Some(why);
                    }
                    Err(load) => {
                        self.last = None;
                        let folder = crate::results::why_none(&r.out_dir, &load)
                            .unwrap_or_else(|| format!("{} holds no results", r.out_dir.display()));
                        self.results_note = Some(format!("{why}; {folder}"));
                    }
                }
                self.page = Page::Log;
                self.say(format!("{} ended ({status}) without results: {e}", r.mode.arg()), true);
            }
        }
    }

    fn trim_log(&mut self) {
        if self.log.len() > LOG_LINES {
            self.log.drain(..self.log.len() - LOG_LINES);
        }
    }

    fn record(&mut self, gains: Vec<(f64, f64, f64)>, r: &MoveResult) {
        let s = &r.summary;
        let what = s.what();
        self.history.push(HistoryEntry {
            n: self.history.len() + 1,
            what,
            fault: s.fault.as_ref().map(|f| f.kind),
            accumulated: s.motors.iter().map(|m| m.accumulated_abs_error_counts).collect(),
            gains,
        });
    }
}
