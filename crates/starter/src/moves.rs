//! One move through the process set, in steps: [`prepare`] checks everything and starts
//! nothing; [`launch`] starts the two children and supervises them to their end;
//! [`conclude`] finds (or writes) the move's summary; [`exit_code`] is docs/usage.md's "Exit codes"
//! table, a pure function of what ended. [`one_move`] runs the four; `qmarc-starter`'s
//! moves, trials and real tuning moves call it.

use crate::companion::Companion;
use crate::ending::{Ended, Ending, conclude, exit_code};
use crate::status::StatusLine;
use crate::supervise::{self, Supervised};
use crate::{Exit, check_iox_root, default_prefix, describe_exit, remove_stale_files, run_file};
use anyhow::{Context, anyhow};
use qmarc_config::{Mode, RunSpec, Settings};
use qmarc_controller::gather::check_budget;
use qmarc_plugins::registry;
use qmarc_proto::exit;
use qmarc_proto::progress::Progress;
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use qmarc_proto::state::Phase;
use qmarc_report::Summary;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A line on standard error that cannot fail: if whoever reads it went away (a closed pipe),
/// the starter still stops its children and removes its files.
#[macro_export]
macro_rules! say {
    ($($t:tt)*) => {{
        let _ = std::io::Write::write_fmt(&mut std::io::stderr(), format_args!("{}\n", format_args!($($t)*)));
    }};
}

/// An error and the exit code it ends the run with.
#[derive(Debug)]
pub struct Failure {
    /// docs/usage.md's exit code.
    pub code: u8,
    /// What went wrong.
    pub error: anyhow::Error,
}

impl From<Failure> for (u8, anyhow::Error) {
    /// As [`qmarc_program::cli::conclude`] takes it.
    fn from(f: Failure) -> Self {
        (f.code, f.error)
    }
}

/// `?` for errors of the user's input: the run is refused.
pub fn refused<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure { code: exit::REFUSED, error: e.into() }
}

/// `?` for everything else.
pub fn internal<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure { code: exit::INTERNAL, error: e.into() }
}

/// What a move is asked to be: the settings (a file and the command line, or given), where
/// the programs and the iceoryx2 files are, and how a trial's move differs.
#[derive(Clone, Copy)]
pub struct MoveRequest<'a> {
    /// The options of every move (settings file, output folder, lock-step…).
    pub opts: &'a crate::cli::MoveOptions,
    /// The move and its own flags.
    pub command: &'a crate::cli::Command,
    /// `--bin-dir`.
    pub bin_dir: Option<&'a Path>,
    /// `--iox-prefix`.
    pub iox_prefix: Option<&'a str>,
    /// `--iox-root`.
    pub iox_root: Option<&'a str>,
    /// `--print-settings`: check, print the run file and start nothing.
    pub print_settings: bool,
    /// How a trial's move differs from a move by hand.
    pub trial: TrialIo<'a>,
}

/// How a trial's move differs from a move by hand.
#[derive(Clone, Copy, Default)]
pub struct TrialIo<'a> {
    /// The output folder instead of the settings'.
    pub out: Option<&'a Path>,
    /// The children's standard error goes here; no table is printed.
    pub log: Option<&'a std::fs::File>,
    /// Check everything, as `--print-settings` does, and start nothing.
    pub check_only: bool,
    /// These settings instead of the file's with the command line's (a tuning's candidate).
    pub settings: Option<&'a Settings>,
}

/// A move checked and ready to start.
pub struct Prepared {
    /// The run both children get.
    pub spec: RunSpec,
    /// Where its iceoryx2 files are.
    pub location: IpcLocation,
    /// The hwserver's program.
    pub hwserver_bin: PathBuf,
    /// The controller's program.
    pub controller_bin: PathBuf,
    /// `qmarc-bridge` and its own options, when `serve --bridge` starts one beside them.
    pub bridge: Option<(PathBuf, Vec<String>)>,
    /// `qmarc-foxglove` and the address of its live view, when `serve --foxglove` starts one.
    pub foxglove: Option<(PathBuf, String)>,
    /// `qmarc-camera`, when the session is at a belt (`conveyor`) of its own.
    pub camera: Option<PathBuf>,
    /// `qmarc-cell`, when the session joins a cell (`conveyor --cell`): the cell's camera
    /// serves it.
    pub cell: Option<PathBuf>,
    /// The iceoryx2 prefix was given (`--iox-prefix`): an earlier run's files under it are
    /// removed before this one starts.
    pub own_prefix: bool,
}

impl Prepared {
    /// The settings of the run.
    pub fn settings(&self) -> &Settings {
        &self.spec.settings
    }

    /// Where the move's data go.
    pub fn out_dir(&self) -> &Path {
        &self.spec.settings.gather.out_dir
    }
}

/// The settings of `req`: given, or the file's with the command line's, in the trial's folder.
fn settings_of(req: &MoveRequest<'_>) -> Result<Settings, Failure> {
    let names = qmarc_plugins::registry::names();
    let mut settings = match req.trial.settings {
        Some(s) => s.clone(),
        None => {
            let mut s = req.opts.load(&names).map_err(refused)?;
            req.command.apply(&mut s, &names).map_err(refused)?;
            s
        }
    };
    if let Some(out) = req.trial.out {
        settings.gather.out_dir = out.to_path_buf();
    }
    Ok(settings)
}

/// The two children's programs in `bin_dir` (`--bin-dir`, or next to this program).
fn programs(bin_dir: Option<&Path>) -> Result<(PathBuf, PathBuf), Failure> {
    let dir = qmarc_program::process::bin_dir(bin_dir).map_err(internal)?;
    let (hwserver, controller) = (dir.join("qmarc-hwserver"), dir.join("qmarc-controller"));
    for b in [&hwserver, &controller] {
        if !b.is_file() {
            return Err(internal(anyhow!(
                "{} not found: build the workspace first (`cargo build --release`)",
                b.display()
            )));
        }
    }
    Ok((hwserver, controller))
}

/// The companion `name` (`qmarc-bridge`, `qmarc-camera`), beside the children's programs.
fn companion_program(hwserver_bin: &Path, name: &str) -> Result<PathBuf, Failure> {
    let program = hwserver_bin.with_file_name(name);
    if !program.is_file() {
        return Err(internal(anyhow!(
            "{} not found: build the workspace first (`cargo build --release`)",
            program.display()
        )));
    }
    Ok(program)
}

/// A conveyor session picks with the Delta and grips with a gripper: both must be there.
fn check_conveyor(s: &Settings) -> Result<(), Failure> {
    if s.robot().is_none() {
        return Err(refused(anyhow!(
            "conveyor picks with the Delta: [robot] must describe it, with three motors \
             (general.n_motors = {})",
            s.n_motors
        )));
    }
    if s.s626.gripper_dio.is_none() {
        return Err(refused(anyhow!(
            "conveyor grips the parts: [s626] gripper_dio = -1 wires no gripper; set it to \
             the gripper's output (config/qmarc.toml has DIO6)"
        )));
    }
    // A camera that finds parts in frames: its frames' source and its calibration.
    if s.camera.backend == "images" {
        qmarc_camera::images::check(&s.camera, s.conveyor.window_mm)
            .map_err(|e| refused(anyhow!("{}: [camera] {e}", s.source.display())))?;
    }
    // The place, and the window's ends on the belt's centre line (a part's grip point and
    // LIFT_MM above it), in reach and inside the motors' soft limits — else no part could be
    // picked, or the loop would find out mid-pick, a fault. (A part seen far off the centre
    // line may be out of reach: it is missed, never chased.)
    let c = &s.conveyor;
    let up = s.camera.part_height_mm;
    let lift = qmarc_session::conveyor::picker::LIFT_MM;
    let mut points = vec![("place_mm".to_string(), c.place_mm)];
    for along in c.window_mm {
        for (what, above) in [("the grip point", up), ("the lift", up + lift)] {
            let at = format!("window_mm: {what} at {along} mm along the centre line");
            points.push((at, c.point_mm(along, 0.0, above)));
        }
    }
    for (what, mm) in points {
        if let Err(e) = s.counts_of_point(mm) {
            return Err(refused(anyhow!("{}: [conveyor] {what}: {e}", s.source.display())));
        }
    }
    Ok(())
}

/// The bridge `command` starts beside its session (`serve --bridge`, `conveyor --bridge`):
/// its program beside `hwserver_bin` and its own options.
fn bridge_of(
    command: &crate::cli::Command,
    hwserver_bin: &Path,
) -> Result<Option<(PathBuf, Vec<String>)>, Failure> {
    Ok(match command {
        crate::cli::Command::Serve(a)
        | crate::cli::Command::Conveyor(crate::cli::ConveyorArgs { serve: a, .. })
            if a.bridge =>
        {
            if let Some(f) = a.zenoh_config.as_ref().filter(|f| !f.is_file()) {
                return Err(refused(anyhow!(
                    "--zenoh-config {}: no such file (a Zenoh configuration, JSON5)",
                    f.display()
                )));
            }
            Some((companion_program(hwserver_bin, "qmarc-bridge")?, a.bridge_args()))
        }
        _ => None,
    })
}

/// The companions of a session at the belt (`conveyor`), checked: its own camera
/// (`qmarc-camera`), or in a cell the cell's companion (`qmarc-cell`: the cell's camera
/// serves it). None for other modes.
fn at_the_belt(
    s: &Settings,
    mode: Mode,
    hwserver_bin: &Path,
) -> Result<(Option<PathBuf>, Option<PathBuf>), Failure> {
    if mode != Mode::Conveyor {
        return Ok((None, None));
    }
    check_conveyor(s)?;
    Ok(if s.cell.name.is_some() {
        (None, Some(companion_program(hwserver_bin, "qmarc-cell")?))
    } else {
        (Some(companion_program(hwserver_bin, "qmarc-camera")?), None)
    })
}

/// The live view `command` starts beside its session (`serve --foxglove [ADDR]`, `conveyor
/// --foxglove`): its program beside `hwserver_bin` and its address, which must be free now.
fn foxglove_of(
    command: &crate::cli::Command,
    hwserver_bin: &Path,
) -> Result<Option<(PathBuf, String)>, Failure> {
    let (crate::cli::Command::Serve(a)
    | crate::cli::Command::Conveyor(crate::cli::ConveyorArgs { serve: a, .. })) = command
    else {
        return Ok(None);
    };
    let Some(addr) = &a.foxglove else { return Ok(None) };
    if let Err(e) = std::net::TcpListener::bind(addr.as_str()) {
        return Err(refused(anyhow!(
            "--foxglove {addr}: cannot serve the live view there: {e} (give another address, \
             HOST:PORT)"
        )));
    }
    Ok(Some((companion_program(hwserver_bin, "qmarc-foxglove")?, addr.clone())))
}

/// Everything is checked before anything starts: the settings, the programs, the iceoryx2
/// location, the hardware, the path, the gather budget and the output folder. Starts
/// nothing, writes nothing.
pub fn prepare(req: &MoveRequest<'_>) -> Result<Prepared, Failure> {
    let settings = settings_of(req)?;
    let mode = req.command.mode();
    let (hwserver_bin, controller_bin) = programs(req.bin_dir)?;
    let bridge = bridge_of(req.command, &hwserver_bin)?;
    let foxglove = foxglove_of(req.command, &hwserver_bin)?;
    let (camera, cell) = at_the_belt(&settings, mode, &hwserver_bin)?;
    crate::companion::zenoh_for(req.command, cell.is_some()).map_err(|e| refused(anyhow!(e)))?;
    let prefix = req.iox_prefix.map_or_else(default_prefix, str::to_string);
    let root = req.iox_root.unwrap_or(DEFAULT_ROOT);
    let location = IpcLocation::checked(&prefix, root).map_err(|e| refused(anyhow!(e)))?;
    check_iox_root(&location.root, req.iox_root.is_some()).map_err(|e| refused(anyhow!(e)))?;
    location.config().map_err(refused)?;
    // A prefix in use by a live run is that run's: refused before anything of it is touched
    // (a second run would fail on its services, and then remove its files).
    // (One whose prefix starts with this one's, or the other way round, counts: a run removes
    // every file that starts with its prefix.)
    if let Some(live) = qmarc_session::discovery::live_run_overlapping(&location.prefix) {
        let whose = if live.prefix == location.prefix {
            format!("iceoryx2 prefix `{}` belongs to", location.prefix)
        } else {
            format!(
                "iceoryx2 prefix `{}` would take the files of `{}`, which belongs to",
                location.prefix, live.prefix
            )
        };
        return Err(refused(anyhow!(
            "{whose} a live {}: {live}; end it first (qmarc cmd --iox-prefix {} quit, or \
             Ctrl-C where it runs) or choose another --iox-prefix",
            if live.serving { "serving session" } else { "run" },
            live.prefix
        )));
    }
    let spec = RunSpec {
        settings,
        mode,
        deterministic: req.opts.lockstep(),
        unpaced: req.opts.unpaced,
        unhomed: req.opts.unhomed,
        iox_prefix: location.prefix.clone(),
        iox_root: location.root.clone(),
        epoch_ns: 0,
    };
    let settings = &spec.settings;
    if spec.unpaced && settings.hwserver.backend != qmarc_config::BackendKind::Sim {
        return Err(refused(anyhow!(
            "--unpaced runs only on the simulated robot (`--backend sim`), not on `{}`: real \
             hardware moves in real time",
            settings.hwserver.backend
        )));
    }
    if spec.deterministic && settings.cell.name.is_some() {
        return Err(refused(anyhow!(
            "a cell's robots share one belt in real time: --cell not with --deterministic"
        )));
    }
    if spec.unpaced && mode.serving() {
        return Err(refused(anyhow!(
            "serve waits for commands in real time: not with --unpaced (--deterministic paces \
             the simulated robot's lock-step by the timer)"
        )));
    }
    // The hardware: there, usable and as the settings describe it (a missing device fails
    // here, at once, naming it).
    qmarc_hwserver::backends::check(settings, spec.deterministic).map_err(refused)?;
    check_path(settings, mode)?;
    let own_prefix = req.iox_prefix.is_some();
    Ok(Prepared {
        spec,
        location,
        hwserver_bin,
        controller_bin,
        bridge,
        foxglove,
        camera,
        cell,
        own_prefix,
    })
}

/// The path: knot files are read and checked now (streams are the controller's to read: it
/// inherits standard input), and its data must fit the gather budget and the disk.
fn check_path(settings: &Settings, mode: Mode) -> Result<(), Failure> {
    // A serving session has no path: it gathers its last gather.stream_max_s, as a stream.
    let planned = if mode.serving() {
        None
    } else {
        let generator = qmarc_controller_process::run::generator_name(mode, settings);
        let entry = registry::generator(generator)
            .with_context(|| format!("no trajectory generator `{generator}`"))
            .map_err(refused)?;
        (entry.build)(settings).map_err(refused)?.samples()
    };
    let settle = qmarc_controller_process::run::settle_cycles(settings, mode);
    let samples = planned
        .unwrap_or(qmarc_controller_process::run::stream_gather_samples(settings, mode))
        + settle;
    check_budget(samples, settings.gather.every).map_err(refused)?;
    let rows = samples.div_ceil(u64::from(settings.gather.every));
    qmarc_report::output::check(
        &settings.gather.out_dir,
        qmarc_report::output::estimate_bytes(rows, settings.n_motors),
    )
    .map_err(refused)
}

/// What a serving session says once it serves: its prefix, its output folder, how to
/// command it.
fn serving_words(p: &Prepared) -> String {
    let out = p.out_dir();
    let out = std::path::absolute(out).unwrap_or_else(|_| out.to_path_buf());
    let prefix = &p.location.prefix;
    format!(
        "qmarc-starter: serving under iceoryx2 prefix {prefix}, data to {}\n  command it: \
         qmarc cmd --iox-prefix {prefix} status | move --xyz X,Y,Z | path FILE | grip on|off | \
         stop | quit (Ctrl-C here ends it too)",
        out.display()
    )
}

/// How long a stopped (SIGSTOP) child may stay stopped before it has stopped responding: as
/// long as the other process would wait for it (the hwserver's watchdog, the controller's
/// response timeout). In lock-step the other waits for as long as it lives (simulated time
/// sees no stall): so does the starter.
pub fn stall_limit(spec: &RunSpec) -> Duration {
    let hw = &spec.settings.hwserver;
    if spec.deterministic {
        Duration::MAX
    } else {
        Duration::from_secs_f64(
            spec.settings.period_s()
                * f64::from(hw.watchdog_periods.max(hw.response_timeout_periods)),
        )
    }
}

/// Starts the two children on `p`'s run file and supervises them to their end (their
/// standard error to `log`, if given); the run's shared-memory files are removed afterwards.
/// The caller holds the output folder's lock ([`qmarc_report::output::lock`]) from before
/// this until the summary is concluded.
pub fn launch(p: &Prepared, log: Option<&std::fs::File>) -> Result<Ended, Failure> {
    remove_stale_files(&p.location.root);
    if p.own_prefix {
        crate::remove_own_stale_files(&p.location);
    }
    let stop = qmarc_timer::stop::install().map_err(internal)?;
    let progress = Progress::create(&Progress::path(&p.location.prefix)).ok();
    // The one settings value both children get, next to the run's shared memory.
    let run = run_file(&p.location.prefix);
    // The run's world (the simulated belt and camera) starts now, for every child alike.
    let epoch_ns = qmarc_timer::clock::monotonic_now_ns();
    RunSpec { epoch_ns, ..p.spec.clone() }.write(&run).map_err(internal)?;
    // In a cell, the cell's world: the robot joins first (refused, nothing has started).
    let cell = crate::companion::join(p.cell.as_deref(), (&p.spec, &p.location, &run), log, stop)
        .map_err(|(code, why)| Failure { code, error: anyhow!(why) })?;
    let child_args = [format!("--settings={}", run.display())];
    // The children inherit this mask; the hwserver and the servo thread then pin themselves.
    if let Err(e) = qmarc_timer::cpus::keep_off(&p.settings().timer.rt_cpus()) {
        say!("qmarc-starter: warning: cannot keep off the real-time CPUs ({e})");
    }
    let mut children = spawn_both(p, &child_args, log)?;
    let mut companions: Vec<Companion> = p
        .bridge
        .iter()
        .map(|(b, args)| Companion::bridge(b, args, &p.location, log))
        .chain(p.foxglove.iter().map(|(f, addr)| Companion::foxglove(f, addr, &p.location, log)))
        .chain(p.camera.iter().map(|c| Companion::camera(c, &child_args, log)))
        .chain(cell)
        .collect();
    let status = std::cell::RefCell::new(StatusLine::new(progress.as_ref()));
    let said = |s: &Supervised| {
        status.borrow_mut().clear();
        match (s.exit, s.unresponsive) {
            (Some(exit), _) if !exit.success() => {
                say!("qmarc-starter: {}", describe_exit(s.name, exit))
            }
            (None, Some(u)) => say!("qmarc-starter: {}; ending the run", u.describe(s.name)),
            _ => {}
        }
    };
    let limit = stall_limit(&p.spec);
    // A serving session says, once its loop serves, where it is and how to command it.
    let mut announce = p.spec.mode.serving().then(|| serving_words(p));
    supervise::wait_all(&mut children, stop, limit, said, || {
        let serving = progress.as_ref().is_some_and(|pg| pg.read().phase == Phase::Moving.wire());
        if serving && let Some(words) = announce.take() {
            status.borrow_mut().clear();
            say!("{words}");
        }
        status.borrow_mut().update();
        for c in &mut companions {
            c.watch(&mut status.borrow_mut());
        }
    });
    for mut c in companions {
        // A death between the last look and the session's end is said too.
        c.watch(&mut status.borrow_mut());
        c.stop();
    }
    status.borrow_mut().clear();
    let reached = progress.as_ref().map(Progress::read);
    drop(progress);
    // A controller that died (a signal, a panic, an internal failure: no summary of its own)
    // left its rows in the gather page: taken before the run's files go. One that ended with
    // a code of the table (ok, a fault, refused, rescued, interrupted) wrote its own.
    let died = children.iter().any(|c| {
        c.name == "qmarc-controller"
            && !matches!(c.exit, Some(Exit::Code(0 | 2 | 3 | 4 | 130)) | None)
    });
    let salvaged = died
        .then(|| {
            qmarc_controller::gather::Gather::salvage(&qmarc_proto::gather_page::GatherPage::path(
                &p.location.prefix,
            ))
        })
        .flatten();
    p.location.remove_files();
    Ok(Ended { children, reached, stop, salvaged })
}

/// The hwserver, then the controller. The hwserver has nothing to save: 3 s to end by
/// itself, 2 s after SIGTERM. The controller may be writing a long move's data: two minutes
/// to end by itself, and after SIGTERM (which it answers within a second, writing or not)
/// 10 s. A controller that cannot start stops the hwserver.
fn spawn_both(
    p: &Prepared,
    args: &[String],
    log: Option<&std::fs::File>,
) -> Result<Vec<Supervised>, Failure> {
    let hwserver = supervise::spawn_logged(&p.hwserver_bin, args, log)
        .with_context(|| format!("cannot start {}", p.hwserver_bin.display()))
        .map_err(|e| {
            p.location.remove_files();
            internal(e)
        })?;
    let secs = Duration::from_secs;
    let mut children = vec![Supervised::new("qmarc-hwserver", hwserver, secs(3), secs(2))];
    match supervise::spawn_logged(&p.controller_bin, args, log) {
        Ok(c) => children.push(Supervised::new("qmarc-controller", c, secs(120), secs(10))),
        Err(e) => {
            say!("qmarc-starter: cannot start {}: {e}", p.controller_bin.display());
            qmarc_program::process::send(&children[0].child, nix::sys::signal::Signal::SIGTERM);
        }
    }
    Ok(children)
}

/// How a move ended: its exit code, its summary and the folder it is in, and the robot of
/// its settings (for the end-effector plots).
pub struct Outcome {
    /// docs/usage.md's exit code.
    pub code: u8,
    /// The summary and its folder.
    pub summary: Option<(Summary, PathBuf)>,
    /// The settings' robot.
    pub robot: Option<qmarc_kinematics::Robot>,
}

/// One move: prepared, launched, concluded; the summary's table printed unless it is a
/// trial's (which logs). With `--print-settings` or a trial's `check_only`, only prepared.
pub fn one_move(req: &MoveRequest<'_>) -> Result<Outcome, Failure> {
    let p = prepare(req)?;
    if req.print_settings || req.trial.check_only {
        if req.print_settings {
            println!("{}", p.spec.to_json());
        }
        return Ok(Outcome { code: exit::OK, summary: None, robot: None });
    }
    // The folder is this run's from before the children start until its summary is final.
    let lock = qmarc_report::output::lock(p.out_dir()).map_err(refused)?;
    let ended = launch(&p, req.trial.log)?;
    let summary = conclude(&p.spec, &ended);
    drop(lock);
    match &summary {
        Some(_) if req.trial.log.is_some() => {}
        Some((s, _)) => {
            let _ = write!(std::io::stdout(), "{}", qmarc_report::table::render(s));
        }
        None => say!(
            "qmarc-starter: no move was made{}",
            if ended.stopped() { ": interrupted before it began" } else { "" }
        ),
    }
    let code = exit_code(&Ending {
        summary: summary.as_ref().map(|(s, _)| s),
        controller: ended.controller(),
        all_clean: ended.all_clean(),
        unresponsive: ended.unresponsive().is_some(),
        stopped: ended.stopped(),
    });
    Ok(Outcome { code, summary, robot: p.settings().robot() })
}
