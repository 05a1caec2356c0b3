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
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A path whose last command moves slower than this (counts/s) ends at rest.
pub const END_AT_REST_COUNTS_PER_S: f64 = 1.0;

/// Files of a move's data, in the output directory.
pub const OUTPUT_FILES: [&str; 3] = ["gather.csv", "gather.m", "summary.json"];

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
    /// An output file could not be written.
    #[error("cannot write {file}: {source}")]
    Output {
        /// The file.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
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
    remove_outputs(&out_dir);

    let plan = plan_for(settings, mode, opts.deterministic, opts.unhomed);
    let n_motors = settings.n_motors;
    let homing = matches!(mode, Mode::Home);
    let mut servo = Servo::new(
        plan,
        (entry.build)(settings)?,
        (law_entry.build)(settings),
        Box::new(MonotonicClock),
    );
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
    write_outputs(&out_dir, &servo, &summary)?;
    Ok(summary)
}

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
        cycles: servo.cycles(),
        planned_samples: servo.planned_samples(),
        period_us: settings.period_us,
        gather_every: settings.gather.every,
        gathered_rows: servo.gather().rows().len() as u64,
        counts_per_rad: cpr,
        motors: servo.errors().axes[..n].iter().map(|e| MotorSummary::new(e, cpr)).collect(),
        gains_period_us: settings.gains_period_us,
        gains: (0..n).map(|m| settings.effective_gains(m).into()).collect(),
        settle,
        timing: TimingSummary::new(servo.timing(), settings.timer.method.name(), &rt.policy()),
        warnings,
        homing: None,
    }
}

/// Removes the data files of an earlier move from `dir`, so that a failed move never leaves
/// stale results looking like its own.
pub fn remove_outputs(dir: &Path) {
    for f in OUTPUT_FILES {
        let _ = std::fs::remove_file(dir.join(f));
    }
}

/// Writes `path` through a temporary file renamed into place, so that a reader (or a kill)
/// never sees half a file.
fn write_file(
    path: PathBuf,
    body: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), RunError> {
    let mut tmp = path.clone().into_os_string();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let result = std::fs::File::create(&tmp).and_then(|f| {
        let mut w = std::io::BufWriter::new(f);
        body(&mut w)?;
        w.flush()?;
        std::fs::rename(&tmp, &path)
    });
    result.map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        RunError::Output { file: path.clone(), source }
    })
}

/// Writes `summary.json` (first: it is small and says what happened), then `gather.csv` and
/// `gather.m`, into `dir` (created if missing).
pub fn write_outputs(dir: &Path, servo: &Servo, summary: &Summary) -> Result<(), RunError> {
    std::fs::create_dir_all(dir)
        .map_err(|source| RunError::Output { file: dir.to_path_buf(), source })?;
    write_file(dir.join("summary.json"), |w| {
        serde_json::to_writer_pretty(&mut *w, summary).map_err(std::io::Error::other)?;
        writeln!(w)
    })?;
    write_file(dir.join("gather.csv"), |w| servo.gather().write_csv(w))?;
    write_file(dir.join("gather.m"), |w| servo.gather().write_octave(w))
}
