//! [`run_move`]: one move from checked settings to files on disk.
//!
//! The servo thread is made SCHED_FIFO (or runs degraded), connects to the hwserver, runs
//! the move, tells the hwserver to exit and hands everything back; this thread then writes
//! `gather.csv`, `gather.m` and `summary.json`. Formatting and file I/O happen only here,
//! after the loop.

use crate::cli::Mode;
use crate::config::Settings;
use crate::link::{HwLink, IoxLink, LinkConnectError, LinkTimeouts};
use crate::registry;
use crate::servo::{MoveError, MoveLimits, MovePlan, Servo};
use crate::summary::{MotorSummary, SettleSummary, Summary, TimingSummary};
use qmarc_proto::service::IpcLocation;
use qmarc_proto::{HwMsg, MAX_MOTORS, MotorFlags, MsgType};
use qmarc_timer::MonotonicClock;
use qmarc_timer::rt::{DmaLatencyGuard, RtRequest, RtStatus};
use std::io::Write;
use std::path::Path;
use std::time::Duration;

/// A path whose last command moves slower than this (counts/s) ends at rest.
pub const END_AT_REST_COUNTS_PER_S: f64 = 1.0;

/// Files of a move's data, in the output directory, in the order they are put in place
/// (`summary.json` last: once it is there, the set is complete).
pub const OUTPUT_FILES: [&str; 3] = ["gather.csv", "gather.m", "summary.json"];

/// How long the servo thread may take to end after a stop signal before the controller
/// exits without it (it is then blocked outside the loop, where nothing is enabled; the
/// hwserver, which got the same signal, has disabled the motors).
pub const STOP_GRACE: Duration = Duration::from_secs(2);

/// A move could not run (nothing was enabled, or the outputs could not be written).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// No generator is registered for the mode.
    #[error("no trajectory generator is registered for mode `{0}`")]
    UnknownMode(String),
    /// The trajectory could not be built (a bad knot file).
    #[error(transparent)]
    Trajectory(#[from] crate::traj::TrajBuildError),
    /// The hwserver could not be reached.
    #[error(transparent)]
    Connect(#[from] LinkConnectError),
    /// The move could not start.
    #[error(transparent)]
    Move(#[from] MoveError),
    /// The servo thread could not be started or died.
    #[error("servo thread: {0}")]
    Thread(String),
    /// The data files could not be written, not even to the rescue folder.
    #[error(transparent)]
    Output(#[from] crate::output::WriteError),
    /// A stop signal ended the run before the move began.
    #[error("interrupted by {signal} before the move began: nothing was enabled")]
    Interrupted {
        /// The signal's name.
        signal: &'static str,
    },
}

impl RunError {
    /// The exit code for this error ([`qmarc_proto::exit`]): the user's input refused
    /// before anything moved, a stop signal, or an internal failure.
    pub fn exit_code(&self) -> u8 {
        use qmarc_proto::exit;
        match self {
            RunError::Interrupted { .. } => exit::INTERRUPTED,
            RunError::Move(MoveError::Trajectory(crate::traj::TrajStartError::Interrupted {
                ..
            })) => exit::INTERRUPTED,
            RunError::UnknownMode(_)
            | RunError::Trajectory(_)
            | RunError::Move(
                MoveError::Trajectory(_)
                | MoveError::NotHomed { .. }
                | MoveError::OutsideSoftLimits { .. }
                | MoveError::Refused(_)
                | MoveError::Gather(_),
            ) => exit::REFUSED,
            _ => exit::INTERNAL,
        }
    }
}

/// How to run a move besides its settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    /// Where the hwserver's services are.
    pub location: IpcLocation,
    /// Lock-step simulated time.
    pub deterministic: bool,
    /// How long to wait for the hwserver to appear.
    pub connect_wait: Duration,
    /// Move in a frame that may not be homed (software limits off).
    pub unhomed: bool,
}

/// Runs `mode` with `settings` against the hwserver at `opts.location`, writes the data
/// files into `settings.gather.out_dir` and returns the summary (also on a fault: a fault is
/// a result, not an error).
pub fn run_move(settings: &Settings, mode: &Mode, opts: &RunOptions) -> Result<Summary, RunError> {
    let generator = mode.generator(settings);
    let entry =
        registry::generator(generator).ok_or_else(|| RunError::UnknownMode(generator.into()))?;
    let law_entry =
        registry::law(&settings.law).ok_or_else(|| RunError::UnknownMode(settings.law.clone()))?;
    let out_dir = settings.gather.out_dir.clone();
    let progress =
        crate::progress::Progress::open(&crate::progress::Progress::path(&opts.location.prefix))
            .ok();

    let plan = plan_for(settings, mode, opts.deterministic, opts.unhomed);
    let n_motors = settings.n_motors;
    let homing = matches!(mode, Mode::Home);
    let mut servo = Servo::new(
        plan,
        (entry.build)(settings)?,
        (law_entry.build)(settings),
        Box::new(MonotonicClock),
    )
    .with_progress(progress);
    let mut ticker = settings.timer.method.build(settings.period_ns());
    let period = settings.period_ns();
    // In lock-step the hwserver is lost only when its process is gone: a host stall is not
    // the simulated robot's time. The liveness check still runs every deadline.
    let timeouts = LinkTimeouts {
        deadline_ns: u64::from(settings.hwserver.deadline_periods) * period,
        give_up_ns: if opts.deterministic {
            u64::MAX
        } else {
            u64::from(settings.hwserver.response_timeout_periods) * period
        },
    };
    let req = RtRequest {
        priority: (settings.timer.servo_priority > 0).then_some(settings.timer.servo_priority),
        lock_memory: settings.timer.lock_memory,
        prefault_stack_bytes: 128 * 1024,
    };
    let location = opts.location.clone();
    let wait = opts.connect_wait;
    let handle = qmarc_timer::rt::spawn("qmarc-servo", req, move |rt: RtStatus| {
        let _dma = DmaLatencyGuard::request_zero();
        let mut homed_read = None;
        let result = (|| -> Result<(), RunError> {
            let stop = qmarc_timer::stop::flag();
            let mut link = IoxLink::connect(&location, timeouts, wait)?.with_stop(stop);
            let moved = servo.run(&mut link, ticker.as_mut(), stop);
            // Homing ends with every motor at its home offset: home reads 0 from now on and the
            // frame is homed (thesis 3.10.1.1). Each motor's position is preset to where it
            // stands relative to home, so the frame does not depend on how well it settled.
            if let (Ok(()), None, Some(home)) = (&moved, servo.fault(), servo.homed_frame()) {
                let now = link.exchange(&HwMsg::read_all_encoders()).map_err(MoveError::from)?;
                let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS);
                for ((p, now), home) in
                    preset.data.iter_mut().zip(now.data).zip(home).take(n_motors)
                {
                    *p = now - home;
                }
                link.exchange(&preset).map_err(MoveError::from)?;
                homed_read =
                    Some(link.exchange(&HwMsg::read_all_encoders()).map_err(MoveError::from)?);
            }
            // The thesis' last message: the hwserver makes the hardware safe and exits.
            if !crate::servo::server_gone(servo.fault()) {
                let _ = link.exchange(&HwMsg::request(MsgType::Exit));
            }
            moved.map_err(RunError::from)
        })();
        (servo, rt, result, homed_read)
    })
    .map_err(|e| RunError::Thread(e.to_string()))?;
    // The servo thread ends by itself on a stop signal, motors disabled first. Should it be
    // blocked outside the loop (nothing enabled), the controller does not wait for it.
    let mut stopped_at: Option<std::time::Instant> = None;
    while !handle.is_finished() {
        if qmarc_timer::stop::requested()
            && stopped_at.get_or_insert_with(std::time::Instant::now).elapsed() > STOP_GRACE
        {
            let signal = qmarc_timer::stop::signal().map_or("a stop signal", signal_name);
            return Err(RunError::Interrupted { signal });
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let (servo, rt, result, homed_read) =
        handle.join().map_err(|_| RunError::Thread("panicked".into()))?;
    result?;

    let mut summary = summarize(settings, &servo, &rt, opts.deterministic);
    if homing {
        // Where each motor's switch was found and where it ended, and what the hwserver says
        // right after the counters were zeroed there.
        let n = settings.n_motors;
        let after = homed_read.map(|r| {
            serde_json::json!({
                "positions_counts": r.data[..n],
                "homed": r.aux[..n].iter().map(|&f| MotorFlags(f).homed()).collect::<Vec<_>>(),
            })
        });
        summary.homing =
            Some(serde_json::json!({ "motors": servo.generator_summary(), "after": after }));
    }
    if opts.unhomed && !homing {
        summary.warnings.push(
            "--unhomed: the frame may not be homed; software position limits were off".into(),
        );
    }
    write_results(&out_dir, &servo, &mut summary)?;
    Ok(summary)
}

pub use qmarc_timer::stop::signal_name;

/// The plan of `mode` with `settings`: the limits of the settings, software limits only in a
/// homed frame (off when homing or with `--unhomed`), homing required unless homing or
/// `--unhomed`, the hwserver's switch latch off while homing.
pub fn plan_for(settings: &Settings, mode: &Mode, deterministic: bool, unhomed: bool) -> MovePlan {
    let homing = matches!(mode, Mode::Home);
    let mut limits = MoveLimits::none();
    let mut soft = [(f64::NEG_INFINITY, f64::INFINITY); MAX_MOTORS];
    for (m, s) in settings.safety.iter().enumerate().take(settings.n_motors) {
        soft[m] = (s.soft_limits[0], s.soft_limits[1]);
        limits.max_following_error[m] = s.max_following_error_counts;
        limits.max_integrated_error[m] = s.max_integrated_error_counts;
    }
    limits.soft = (!homing && !unhomed).then_some(soft);
    // Lock-step time is simulated: a host stall skips no sample there, so it is no overrun.
    limits.max_missed_in_row = if deterministic { u64::MAX } else { settings.max_missed_in_row };
    MovePlan {
        gather_every: settings.gather.every,
        gather_fields: settings.gather.fields,
        deterministic,
        starve_hold_cycles: (settings.trajectory.starve_hold_ms * 1e6 / settings.period_ns() as f64)
            .ceil() as u64,
        // Homing settles every motor at home itself.
        settle_cycles: if homing {
            0
        } else {
            (settings.trajectory.settle_s / settings.period_s()).round() as u64
        },
        limits,
        require_homed: !homing && !unhomed,
        monitor_switches: !homing,
        ..MovePlan::new(mode.name(), settings.n_motors, settings.period_ns())
    }
}

/// The summary of a finished move.
pub fn summarize(
    settings: &Settings,
    servo: &Servo,
    rt: &RtStatus,
    deterministic: bool,
) -> Summary {
    let cpr = settings.counts_per_rad();
    let n = settings.n_motors;
    let mut warnings = rt.warnings.clone();
    if servo.gather().dropped() > 0 {
        warnings.push(format!("{} gathered rows did not fit the buffer", servo.gather().dropped()));
    }
    if let Some(v) = servo.end_velocity()
        && let Some(m) = (0..n).find(|&m| v[m].abs() > END_AT_REST_COUNTS_PER_S)
    {
        warnings.push(format!(
            "the path ends moving (motor {} at {:.1} counts/s): its last command was held for \
             trajectory.settle_s = {} s so that the motors stop under control; end the path at \
             rest (a last knot repeated, or a PVT velocity of 0) to avoid the jolt",
            m + 1,
            v[m],
            settings.trajectory.settle_s
        ));
    }
    if settings.gains_rescaled() {
        warnings.push(format!(
            "the gains were tuned at general.gains_period_us = {} µs and run at {} µs: Kd and \
             Kvff × {r}, Kaff × {r2}, Ki ÷ {r} (the effective gains are in summary.json)",
            settings.gains_period_us,
            settings.period_us,
            r = f64::from(settings.gains_period_us) / f64::from(settings.period_us),
            r2 = (f64::from(settings.gains_period_us) / f64::from(settings.period_us)).powi(2),
        ));
    }
    // The error at the end: of the settle, or of the path when there was none.
    let final_error = match servo.settle_figures() {
        Some((_, _, last)) => last,
        None => servo.last_error(),
    };
    let mut motors: Vec<MotorSummary> =
        servo.errors().axes[..n].iter().map(|e| MotorSummary::new(e, cpr)).collect();
    let mut travel = servo.errors().travel;
    if let Some((_, settled, _)) = servo.settle_figures() {
        for (t, s) in travel.iter_mut().zip(&settled.travel) {
            t.add(s.act.0, s.act.0);
            t.add(s.act.1, s.act.1);
        }
    }
    for (m, summary) in motors.iter_mut().enumerate() {
        if travel[m].not_followed(final_error[m]) {
            summary.followed = false;
            let (commanded, moved) = travel[m].lengths();
            warnings.push(format!(
                "motor {} did not follow its command: it moved {moved:.0} of the {commanded:.0} \
                 counts commanded and ended {:.0} counts from its last command (a seized joint, \
                 an amplifier that is off or not wired, a gain of the wrong sign?)",
                m + 1,
                final_error[m]
            ));
        }
    }
    let settle = servo.settle_figures().map(|(cycles, errors, last)| SettleSummary {
        cycles,
        seconds: (cycles * u64::from(settings.period_us)) as f64 / 1e6,
        final_error_counts: last[..n].to_vec(),
        max_abs_error_counts: errors.axes[..n]
            .iter()
            .map(|e| e.max.abs().max(e.min.abs()))
            .collect(),
    });
    Summary {
        mode: servo.plan().mode.clone(),
        trajectory: servo.generator_name().to_string(),
        ok: servo.fault().is_none(),
        degraded: rt.degraded(),
        deterministic,
        fault: servo.fault_report(),
        n_motors: n,
        cycles: servo.cycles(),
        planned_samples: servo.planned_samples(),
        period_us: settings.period_us,
        gather_every: settings.gather.every,
        gathered_rows: servo.gather().rows().len() as u64,
        counts_per_rad: cpr,
        motors,
        gains_period_us: settings.gains_period_us,
        gains: (0..n).map(|m| settings.effective_gains(m).into()).collect(),
        settle,
        timing: TimingSummary::new(servo.timing(), settings.timer.method.name(), &rt.policy()),
        warnings,
        starter_pid: nix::unistd::getppid().as_raw() as u32,
        files: Vec::new(),
        homing: None,
    }
}

/// Writes the move's data files and `summary.json` into `dir` as one set
/// ([`crate::output::write_set`]): the previous results stay until all of them are written.
/// The stop that ended the move does not cut the writing short; a further stop signal while
/// the rows are written abandons the data files (the summary is still written, with a
/// warning); a failure writes everything to the rescue folder instead, with a warning, and
/// says so on standard error.
pub fn write_results(dir: &Path, servo: &Servo, summary: &mut Summary) -> Result<(), RunError> {
    let gather = servo.gather();
    let csv = |w: &mut dyn Write| gather.write_csv(w);
    let octave = |w: &mut dyn Write| gather.write_octave(w);
    let attempt = |dir: &Path, summary: &mut Summary, data: bool| {
        let names: &[&str] = if data { &OUTPUT_FILES } else { &OUTPUT_FILES[2..] };
        summary.files = names.iter().map(|f| dir.join(f)).collect();
        let frozen = summary.clone();
        let json = move |w: &mut dyn Write| {
            serde_json::to_writer_pretty(&mut *w, &frozen).map_err(std::io::Error::other)?;
            writeln!(w)
        };
        let all: [crate::output::FileWriter<'_>; 3] =
            [("gather.csv", &csv), ("gather.m", &octave), ("summary.json", &json)];
        crate::output::write_set(dir, if data { &all } else { &all[2..] })
    };
    let Err(e) = attempt(dir, summary, true) else { return Ok(()) };
    if crate::output::interrupted(&e) {
        summary.warnings.push(format!(
            "a second stop signal arrived while the data were written: gather.csv and \
             gather.m were not written (in {} the previous ones, if any, are as they were)",
            dir.display()
        ));
        attempt(dir, summary, false)?;
        return Ok(());
    }
    let rescue = crate::output::rescue_dir(nix::unistd::getppid().as_raw() as u32);
    let warning = format!("{e}; the data of this move are in {} instead", rescue.display());
    let _ = writeln!(std::io::stderr(), "qmarc-controller: {warning}");
    summary.warnings.push(warning);
    attempt(&rescue, summary, true)?;
    Ok(())
}
