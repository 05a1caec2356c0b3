//! `qmarc-starter tune`: picks how candidates are evaluated — lock-step inside this process
//! on the simulated robot, real moves through [`one_move`] otherwise — shows the progress and
//! prints the before/after table and the tuned gains ([`qmarc_starter::tune`] does the rest).

use crate::{Failure, StarterArgs, TrialIo, internal, one_move, refused};
use anyhow::anyhow;
use qmarc_config::{Mode, Settings};
use qmarc_plugins::registry::names;
use qmarc_proto::exit;
use qmarc_starter::cli::{Command, RunArgs, StepArgs};
use qmarc_starter::tune::TuneArgs;
use qmarc_tune::eval::{EvalError, SimEvaluator};
use qmarc_tune::optimise::Record;
use qmarc_tune::real::RealEvaluator;
use qmarc_tune::report;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// How often a line of progress is printed when no terminal shows the bar.
const PROGRESS_EVERY: Duration = Duration::from_millis(250);

/// The settings of `tune` (the file's, the command line's and the tuning's own flags) and
/// whether its candidates are real moves; refused where a tuning would not be safe or sound.
fn tune_settings(args: &StarterArgs, t: &TuneArgs) -> Result<(Settings, bool), Failure> {
    let names = names();
    let mut settings = args.opts.load(&names).map_err(refused)?;
    Command::Run(t.run_args().clone()).apply(&mut settings, &names).map_err(refused)?;
    t.apply(&mut settings).map_err(refused)?;
    if args.print_settings {
        return Err(refused(anyhow!(
            "tune makes moves: check the path with `qmarc-starter --print-settings run …`"
        )));
    }
    let real = t.paced || settings.hwserver.backend != qmarc_config::BackendKind::Sim;
    if real && args.opts.unpaced {
        return Err(refused(anyhow!(
            "--unpaced is the simulated robot's lock-step: tuning with --paced or on `{}` \
             makes real moves in real time",
            settings.hwserver.backend
        )));
    }
    if real && args.opts.unhomed {
        return Err(refused(anyhow!(
            "--unhomed turns the software limits off: real moves tune only in a homed frame"
        )));
    }
    if real && settings.tune.margin > 1.0 + settings.tune.max_change {
        return Err(refused(anyhow!(
            "tune.margin = {} would run the stability step with the feedback gains more than \
             tune.max_change = {} beyond the best ones: on real moves keep margin ≤ 1 + max_change",
            settings.tune.margin,
            settings.tune.max_change
        )));
    }
    Ok((settings, real))
}

/// Real moves run the path back to back, so it must end where it starts.
fn check_back_to_back(settings: &Settings, first: &[f64], last: &[f64]) -> Result<(), Failure> {
    let far = (0..settings.n_motors)
        .find(|&m| (first[m] - last[m]).abs() > settings.trajectory.start_tolerance_counts);
    match far {
        Some(m) => Err(refused(anyhow!(
            "real moves run the path back to back, so it must end where it starts: motor {} \
             starts at {:.0} and ends at {:.0} counts",
            m + 1,
            first[m],
            last[m]
        ))),
        None => Ok(()),
    }
}

/// Tuning by real moves, each through the process set ([`one_move`]) into `out/moves`, the
/// processes' messages into `log` (at `log_path`).
fn tune_by_real_moves(
    args: &StarterArgs,
    settings: &Settings,
    out: &std::path::Path,
    (log, log_path): (&std::fs::File, &std::path::Path),
    stop: &'static std::sync::atomic::AtomicBool,
    on_record: &mut dyn FnMut(&Record),
) -> anyhow::Result<qmarc_starter::tune::TuneOutcome> {
    let moves = out.join("moves");
    let mut mover =
        |mode: Mode, s: &Settings| -> Result<(qmarc_report::Summary, PathBuf), String> {
            let command = match mode {
                Mode::Step => Command::Step(StepArgs::default()),
                _ => Command::Run(RunArgs::default()),
            };
            let io =
                TrialIo { out: Some(&moves), log: Some(log), check_only: false, settings: Some(s) };
            let o = one_move(args, &command, io).map_err(|f| format!("{:#}", f.error))?;
            o.summary.ok_or_else(|| {
                format!(
                    "no move was made (exit code {}): the processes say why in {}",
                    o.code,
                    log_path.display()
                )
            })
        };
    let mut eval = RealEvaluator::new(settings, &mut mover, stop);
    qmarc_starter::tune::run(settings, &mut eval, out, None, on_record)
}

/// `tune`: better gains on the path of `t`.
pub(crate) fn tune(args: &StarterArgs, t: &TuneArgs) -> Result<ExitCode, Failure> {
    let (settings, real) = tune_settings(args, t)?;
    let (first, last) = qmarc_tune::local::path_ends(&settings).map_err(|e| refused(anyhow!(e)))?;
    if let Some(w) = &t.write {
        report::check_copy(&settings.source, w).map_err(refused)?;
    }
    let out = args.opts.out.clone().unwrap_or_else(|| settings.gather.out_dir.join("tune"));
    std::fs::create_dir_all(&out)
        .map_err(|e| refused(anyhow!("cannot create {}: {e}", out.display())))?;
    let stop = qmarc_timer::stop::install().map_err(internal)?;
    let bar = progress_bar(&settings)?;
    // Without a terminal (the console, a log file) the bar is not drawn: a line of progress
    // instead, at each motor's first candidate and then every PROGRESS_EVERY.
    let mut last_line: Option<(usize, Instant)> = None;
    let mut on_record = |r: &Record| {
        let line = report::progress_line(r, settings.n_motors, settings.tune.objective.name());
        bar.set_position(r.motor as u64);
        bar.set_message(line.trim_start_matches(report::PROGRESS_PREFIX).to_string());
        if bar.is_hidden()
            && last_line.is_none_or(|(m, at)| m != r.motor || at.elapsed() >= PROGRESS_EVERY)
        {
            println!("{line}");
            last_line = Some((r.motor, Instant::now()));
        }
    };
    let outcome = if real {
        check_back_to_back(&settings, &first, &last)?;
        let log_path = out.join("tune.log");
        let log = std::fs::File::create(&log_path).map_err(internal)?;
        tune_by_real_moves(args, &settings, &out, (&log, &log_path), stop, &mut on_record)
    } else {
        let settings =
            qmarc_tune::local::on_the_path(&settings).map_err(|e| refused(anyhow!(e)))?;
        let spec = qmarc_tune::local::local_spec(settings.clone(), Mode::Run);
        let mut eval = SimEvaluator::new(&spec, stop);
        qmarc_starter::tune::run(&settings, &mut eval, &out, Some(&spec), &mut on_record)
    }
    .map_err(|e| {
        let code = match e.downcast_ref::<EvalError>() {
            Some(EvalError::Interrupted) => exit::INTERRUPTED,
            Some(EvalError::Faulted(_)) => exit::FAULT,
            Some(_) => exit::REFUSED,
            None => exit::INTERNAL,
        };
        Failure { code, error: e.context("tuning") }
    })?;
    bar.finish_and_clear();
    print_outcome(&settings, &outcome, real);
    if let Some(w) = &t.write {
        report::write_copy(
            &settings.source,
            w,
            &outcome.after,
            &qmarc_starter::tune::provenance(&settings),
        )
        .map_err(internal)?;
        println!("  settings with the tuned gains: {}", w.display());
    }
    // The move budget is an end like the optimiser's own; a stop or a fault is not.
    Ok(ExitCode::from(match &outcome.tuned.aborted {
        None | Some(EvalError::MoveBudget(_)) => exit::OK,
        Some(EvalError::Interrupted) => exit::INTERRUPTED,
        Some(_) => exit::FAULT,
    }))
}

/// The bar: the motors done, the candidate, the moves and the best objective so far.
fn progress_bar(settings: &Settings) -> Result<indicatif::ProgressBar, Failure> {
    let bar = indicatif::ProgressBar::new(settings.n_motors as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("tuning {pos}/{len} motors done {elapsed} · {msg}")
            .map_err(internal)?,
    );
    Ok(bar)
}

/// The before/after table, the files and the gains.
fn print_outcome(settings: &Settings, o: &qmarc_starter::tune::TuneOutcome, real: bool) {
    let evaluations = o.tuned.records.len();
    println!(
        "tuned {} on {} by {} ({} candidates, objective {})",
        settings.tune.params.iter().map(|p| p.name()).collect::<Vec<_>>().join(","),
        report::path_name(settings),
        if real { "real moves" } else { "lock-step simulation (the motors are independent there)" },
        evaluations,
        settings.tune.objective,
    );
    if let Some(why) = &o.tuned.aborted {
        println!("  ended early: {why}; the gains below are the last safe ones");
    }
    if let Some(after) = &o.after_run {
        print!("{}", report::table(&o.tuned.before_run, after));
    }
    for f in &o.files {
        println!("  {}", f.display());
    }
    print!("{}", report::fragment(&o.after, "tuned gains (tuned-gains.toml)"));
}
