//! [`run_move`]: one move, from the run the starter hands over to files on disk.
//!
//! The generator and the law come from the registry, the plan from the settings; a
//! SCHED_FIFO thread (or a degraded one) connects to the hwserver, runs the loop, presets
//! the counters after a homing, tells the hwserver to exit and hands everything back; this
//! thread then writes `gather.csv`, `gather.m` and `summary.json`. Formatting and file I/O
//! happen only here, after the loop.

use qmarc_config::{Mode, RunSpec, Settings};
use qmarc_controller::link::{HwLink, IoxLink, LinkConnectError, LinkTimeouts};
use qmarc_controller::plan::{MoveLimits, MovePlan};
use qmarc_controller::record::MoveRecord;
use qmarc_controller::servo::{MoveError, Servo, server_gone};
use qmarc_controller::traj::TrajStartError;
use qmarc_foxglove::recording::Recording;
use qmarc_plugins::registry;
use qmarc_plugins::source::TrajBuildError;
use qmarc_proto::progress::Progress;
use qmarc_proto::service::IpcLocation;
use qmarc_proto::state::FaultKind;
use qmarc_proto::{HwMsg, MAX_MOTORS, MotorFlags, MsgType};
use qmarc_report::Summary;
use qmarc_report::output::WriteError;
use qmarc_report::summarize::summarize;
use qmarc_report::summary::{AfterHoming, HomingReport, Warning, WarningKind};
use qmarc_session::conveyor::dispatch::{Dispatched, Dispatcher};
use qmarc_session::conveyor::picker::{Picker, PickerHandle};
use qmarc_session::generator::ServeHandle;
use qmarc_session::server;
use qmarc_timer::rt::{DmaLatencyGuard, RtRequest, RtStatus};
use qmarc_timer::{MonotonicClock, Ticker, TickerKind, UnpacedTicker};
use std::time::{Duration, Instant};

/// How long the servo thread may take to end after a stop signal before the controller
/// exits without it (it is then blocked outside the loop, where nothing is enabled; the
/// hwserver, which got the same signal, has disabled the motors).
pub const STOP_GRACE: Duration = Duration::from_secs(2);

/// How long the controller waits for the hwserver to appear.
pub const CONNECT_WAIT: Duration = Duration::from_secs(5);

/// A move could not run (nothing was enabled, or the outputs could not be written).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// No generator or law is registered under the name the settings give.
    #[error("nothing is registered as `{0}`")]
    Unregistered(String),
    /// The trajectory could not be built (a bad knot file).
    #[error(transparent)]
    Trajectory(#[from] TrajBuildError),
    /// The iceoryx2 prefix or root of the run is not usable.
    #[error("{0}")]
    Location(String),
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
    Output(#[from] WriteError),
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
            RunError::Interrupted { .. }
            | RunError::Move(MoveError::Trajectory(TrajStartError::Interrupted { .. })) => {
                exit::INTERRUPTED
            }
            RunError::Unregistered(_)
            | RunError::Trajectory(_)
            | RunError::Location(_)
            | RunError::Move(
                MoveError::Trajectory(_)
                | MoveError::NotHomed { .. }
                | MoveError::OutsideSoftLimits { .. }
                | MoveError::Refused(_)
                | MoveError::EmergencyStop
                | MoveError::Gather(_),
            ) => exit::REFUSED,
            _ => exit::INTERNAL,
        }
    }
}

/// What the servo thread hands back: the move, what it was granted, how it ended, and the
/// read right after a homing preset the counters.
type Moved = (Servo, RtStatus, Result<(), RunError>, Option<HwMsg>);

/// The error of a run a stop signal ended before its move began.
fn interrupted() -> RunError {
    let signal =
        qmarc_timer::stop::signal().map_or("a stop signal", qmarc_timer::stop::signal_name);
    RunError::Interrupted { signal }
}

/// `e`, an error before the move began, as the run's end: [`interrupted`] when a stop signal
/// has arrived (a Ctrl-C as the run starts interrupts iceoryx2's calls, or finds the hwserver
/// already shutting down: the user's stop, not a failure nor a refusal). An interruption that
/// says what it interrupted (waiting for the knots) stays as it is.
fn unless_stopped(e: RunError) -> RunError {
    let stopped = qmarc_timer::stop::count() > 0;
    if stopped && e.exit_code() != qmarc_proto::exit::INTERRUPTED { interrupted() } else { e }
}

/// The registered generator `mode` uses with `settings`.
pub fn generator_name(mode: Mode, settings: &Settings) -> &str {
    match mode {
        Mode::Step => "step",
        Mode::Run => &settings.trajectory.method,
        Mode::Home => "home",
        Mode::Jog => "jog",
        Mode::Check => "check",
        Mode::Move if settings.motion.linear => "linear",
        Mode::Move => "move",
        // A conveyor session serves: the picking comes to it as orders.
        Mode::Serve | Mode::Conveyor => "serve",
    }
}

/// Runs `spec` against its hwserver, writes the data files into the settings' output
/// folder and returns the summary (also on a fault: a fault is a result, not an error).
pub fn run_move(spec: &RunSpec) -> Result<Summary, RunError> {
    let settings = &spec.settings;
    let location =
        IpcLocation::checked(&spec.iox_prefix, &spec.iox_root).map_err(RunError::Location)?;
    // Before any thread starts: they inherit the main thread's CPUs (the servo thread then
    // pins itself), and helpers the servo thread spawns return to them.
    if let Err(e) = qmarc_timer::cpus::keep_off(&settings.timer.rt_cpus()) {
        eprintln!("qmarc-controller: warning: cannot keep off the real-time CPUs ({e})");
    }
    let progress = Progress::open(&Progress::path(&location.prefix)).ok();
    let (telemetry, relay) = telemetry_for(settings, &location);
    let (servo, serving, picker) = build_serving(spec, progress)?;
    // The rows in shared memory beside the run's other files: a killed controller leaves
    // them to its starter.
    let page = qmarc_proto::gather_page::GatherPage::path(&location.prefix);
    let servo = servo.with_telemetry(telemetry).with_gather_page(page);
    // Serving: the command thread, answering from before the loop starts until this returns.
    let commands = match serving {
        Some(h) => Some(
            server::CommandThread::spawn(&location, settings, spec.unhomed, h)
                .map_err(|e| RunError::Location(e.to_string()))?,
        ),
        None => None,
    };
    // A conveyor session: the thread between the camera and the loop's picker.
    let dispatcher = match picker {
        Some((h, status)) => Some(
            Dispatcher::spawn(&location, settings, (spec.epoch_ns, !spec.deterministic), h, status)
                .map_err(|e| RunError::Location(e.to_string()))?,
        ),
        None => None,
    };
    let handle = spawn_servo(spec, location, servo)?;
    // The servo thread ends by itself on a stop signal, motors disabled first. Should it be
    // blocked outside the loop (nothing enabled), the controller does not wait for it.
    let mut stopped_at: Option<Instant> = None;
    while !handle.is_finished() {
        if qmarc_timer::stop::requested()
            && stopped_at.get_or_insert_with(Instant::now).elapsed() > STOP_GRACE
        {
            return Err(interrupted());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let (mut servo, rt, result, homed_read) =
        handle.join().map_err(|_| RunError::Thread("panicked".into()))?;
    // The loop lets go of its ring (a move that never began did not): the relay publishes
    // what is left and ends.
    servo.end_telemetry();
    let record = servo.into_record();
    if let Some(c) = &commands {
        c.ended(FaultKind::wire(record.fault.as_ref().map(|f| f.kind)));
    }
    let relayed = relay.map(qmarc_telemetry::relay::Relay::join);
    let dispatched = dispatcher.map(Dispatcher::finish);
    result?;

    let mut summary = summarize(settings, &record, &rt, spec.mode, spec.deterministic);
    if spec.unpaced {
        // No timer paced it: its timing figures measure nothing (the table says so).
        summary.timing.method = qmarc_report::summary::UNPACED.to_string();
    }
    if spec.mode == Mode::Home {
        summary.homing = Some(homing_report(&record, homed_read, settings.n_motors));
    }
    warn(&mut summary, spec, &record, relayed.and_then(|r| r.error));
    write_results(settings, &record, &mut summary, dispatched.as_ref())?;
    Ok(summary)
}

/// Writes the set of files of the move that left `record` (`summary`'s): gather.csv,
/// gather.m, gather.mcap, a conveyor session's parts.csv (from what its dispatcher saw,
/// `dispatched`) and summary.json last.
fn write_results(
    settings: &Settings,
    record: &MoveRecord,
    summary: &mut Summary,
    dispatched: Option<&Dispatched>,
) -> Result<(), WriteError> {
    let (extra, parts) = match dispatched {
        Some(d) => {
            let (csv, section, cell, parts) = crate::conveyor::results(d, &record.gather, settings);
            summary.conveyor = Some(section);
            summary.cell = cell;
            (vec![("parts.csv", csv)], parts)
        }
        None => (Vec::new(), Vec::new()),
    };
    let frozen = summary.clone();
    // The rescue folder is named after the run's starter, this process's parent.
    let starter = std::os::unix::process::parent_id();
    Recording::of(settings, record, &frozen, &parts).write_results(
        &settings.gather.out_dir,
        summary,
        starter,
        &extra,
    )
}

/// The warnings of a move of `spec` that left `record`: a frame that may not be homed, motors
/// whose soft limits did not hold, live telemetry missing (`telemetry_error`) or dropped.
fn warn(
    summary: &mut Summary,
    spec: &RunSpec,
    record: &MoveRecord,
    telemetry_error: Option<String>,
) {
    let n_motors = spec.settings.n_motors;
    if spec.unhomed && spec.mode != Mode::Home {
        summary.warnings.push(Warning::new(
            WarningKind::Unhomed,
            "--unhomed: the frame may not be homed; software position limits were off",
        ));
    }
    let unhomed: Vec<String> =
        (0..n_motors).filter(|&m| !record.homed[m]).map(|m| (m + 1).to_string()).collect();
    if matches!(spec.mode, Mode::Jog | Mode::Check) && !unhomed.is_empty() && !spec.unhomed {
        summary.warnings.push(Warning::new(
            WarningKind::NotHomed,
            format!(
                "motors {} are not homed: the software position limits did not hold for them",
                unhomed.join(", ")
            ),
        ));
    }
    if let Some(why) = telemetry_error {
        summary
            .warnings
            .push(Warning::new(WarningKind::Telemetry, format!("no live telemetry: {why}")));
    }
    if record.telemetry_dropped > 0 {
        summary.warnings.push(Warning::new(
            WarningKind::Telemetry,
            format!(
                "live telemetry: {} samples dropped (its publishing thread fell behind)",
                record.telemetry_dropped
            ),
        ));
    }
}

/// The loop's end of the telemetry ring and the thread publishing it, when
/// `telemetry.enabled`. A thread that cannot start leaves the loop without telemetry, never
/// without its move.
fn telemetry_for(
    settings: &Settings,
    location: &IpcLocation,
) -> (Option<qmarc_controller::telemetry::Telemetry>, Option<qmarc_telemetry::relay::Relay>) {
    if !settings.telemetry.enabled {
        return (None, None);
    }
    let (tx, rx) = qmarc_controller::telemetry::ring(settings.telemetry.every);
    match qmarc_telemetry::relay::spawn(location.clone(), rx) {
        Ok(relay) => (Some(tx), Some(relay)),
        Err(e) => {
            eprintln!("qmarc-controller: no live telemetry: {e}");
            (None, None)
        }
    }
}

/// The move of `spec`: its generator and law from the registry, its plan, and the progress
/// block it reports to (the starter's, for a move of the process set).
pub fn build_servo(spec: &RunSpec, progress: Option<Progress>) -> Result<Servo, RunError> {
    Ok(build_serving(spec, progress)?.0)
}

/// The dispatcher's end of a conveyor session's picker, and the loop's status.
pub type PickerEnd = (PickerHandle, std::sync::Arc<qmarc_controller::status::LoopStatus>);

/// [`build_servo`], and when `spec` serves (`serve`, `conveyor`), the command thread's end of
/// its generator — and a conveyor session's picker's end for its dispatcher.
pub fn build_serving(
    spec: &RunSpec,
    progress: Option<Progress>,
) -> Result<(Servo, Option<ServeHandle>, Option<PickerEnd>), RunError> {
    let settings = &spec.settings;
    let law =
        registry::law(&settings.law).ok_or_else(|| RunError::Unregistered(settings.law.clone()))?;
    let plan = plan_for(settings, spec.mode, spec.deterministic, spec.unhomed);
    // `--unhomed` turns the software limits off: a jog then goes at the unhomed speed, homed
    // frame or not.
    let mut unhomed_jog = settings.clone();
    unhomed_jog.jog.speed = settings.jog.unhomed_speed;
    let settings = if spec.unhomed && spec.mode == Mode::Jog { &unhomed_jog } else { settings };
    // What the loop is doing, as it writes it: the serving session's command thread reads it.
    let status = std::sync::Arc::new(qmarc_controller::status::LoopStatus::default());
    let mut picker = None;
    let (mut path, serving) = if spec.mode == Mode::Conveyor {
        let (generator, handle, picker_end) =
            Picker::new(settings, status.clone()).ok_or_else(|| {
                RunError::Unregistered(
                    "conveyor (the settings describe no Delta: [robot], three motors)".into(),
                )
            })?;
        picker = Some((picker_end, status.clone()));
        (Box::new(generator) as Box<dyn qmarc_controller::traj::TrajectoryGenerator>, Some(handle))
    } else if spec.mode.serving() {
        let (generator, handle) = server::generator(settings, spec.unhomed, status.clone());
        (generator, Some(handle))
    } else {
        let name = generator_name(spec.mode, settings);
        let entry =
            registry::generator(name).ok_or_else(|| RunError::Unregistered(name.to_string()))?;
        ((entry.build)(settings)?, None)
    };
    if spec.mode == Mode::Run && settings.trajectory.approach {
        path = Box::new(qmarc_plugins::moveto::Approach::from_settings(path, settings));
    }
    // The check runs with the loop open: its own law, whatever general.law says.
    let law: Box<dyn qmarc_controller::law::ServoLaw> = match spec.mode {
        Mode::Check => Box::new(qmarc_plugins::check::OpenLoop::from_settings(settings)),
        _ => (law.build)(settings),
    };
    let servo = Servo::new(plan, path, law, Box::new(MonotonicClock))
        .with_progress(progress)
        .with_status(status);
    Ok((servo, serving, picker))
}

/// The ticker of `timer.method` (the benchmark's bare loop takes the same).
pub fn ticker_kind(method: qmarc_config::TimerMethod) -> TickerKind {
    match method {
        qmarc_config::TimerMethod::Timerfd => TickerKind::TimerFd,
        qmarc_config::TimerMethod::Nanosleep => TickerKind::Nanosleep,
        qmarc_config::TimerMethod::TimerfdPeriodic => TickerKind::TimerFdPeriodic,
    }
}

/// Starts the servo thread: SCHED_FIFO as the settings ask, the link, the move (paced by
/// `timer.method`, or not at all with `--unpaced`), the homing preset, the hwserver's exit.
fn spawn_servo(
    spec: &RunSpec,
    location: IpcLocation,
    mut servo: Servo,
) -> Result<std::thread::JoinHandle<Moved>, RunError> {
    let (settings, deterministic) = (&spec.settings, spec.deterministic);
    let period = settings.period_ns();
    let mut ticker: Box<dyn Ticker> = if spec.unpaced {
        Box::new(UnpacedTicker::new(period))
    } else {
        ticker_kind(settings.timer.method).build(period)
    };
    // In lock-step the hwserver is lost only when its process is gone: a host stall is not
    // the simulated robot's time. The liveness check still runs every deadline.
    let timeouts = LinkTimeouts {
        deadline_ns: u64::from(settings.hwserver.deadline_periods) * period,
        give_up_ns: if deterministic {
            u64::MAX
        } else {
            u64::from(settings.hwserver.response_timeout_periods) * period
        },
        spin_ns: u64::from(settings.hwserver.response_spin_us) * 1_000,
    };
    let req = RtRequest {
        priority: (settings.timer.servo_priority > 0).then_some(settings.timer.servo_priority),
        lock_memory: settings.timer.lock_memory,
        prefault_stack_bytes: 128 * 1024,
        cpu: settings.timer.servo_cpu,
    };
    let spinning_server = settings.hwserver.wait == qmarc_config::HwWait::Spin;
    qmarc_timer::rt::spawn("qmarc-servo", req, move |rt: RtStatus| {
        let _dma = DmaLatencyGuard::request_zero();
        let mut homed_read = None;
        let result = (|| -> Result<(), RunError> {
            let stop = qmarc_timer::stop::flag();
            let mut link = match IoxLink::connect(&location, timeouts, CONNECT_WAIT, Some(stop)) {
                Err(LinkConnectError::Stopped) => return Err(interrupted()),
                Ok(link) if spinning_server => link.to_spinning_server(),
                link => link.map_err(|e| unless_stopped(e.into()))?,
            };
            let moved = servo.run(&mut link, ticker.as_mut(), stop);
            if moved.is_ok() {
                homed_read = servo.preset_home(&mut link);
            }
            // The thesis' last message: the hwserver makes the hardware safe and exits.
            if !server_gone(servo.fault()) {
                let _ = link.exchange(&HwMsg::request(MsgType::Exit));
            }
            moved.map_err(|e| unless_stopped(e.into()))
        })();
        (servo, rt, result, homed_read)
    })
    .map_err(|e| RunError::Thread(e.to_string()))
}

/// Homing's part of the summary: where each switch was found and where home is, and what
/// the hwserver read right after the counters were preset.
fn homing_report(record: &MoveRecord, after: Option<HwMsg>, n: usize) -> HomingReport {
    HomingReport {
        motors: qmarc_report::summarize::findings(record, "homing").unwrap_or_default(),
        after: after.map(|r| AfterHoming {
            positions_counts: r.data[..n].to_vec(),
            homed: r.aux[..n].iter().map(|&f| MotorFlags(f).homed()).collect(),
        }),
    }
}

/// Samples the gather buffer holds for a stream: `gather.stream_max_s` of servo periods, or a
/// conveyor session's whole `conveyor.run_s` and its end.
pub fn stream_gather_samples(settings: &Settings, mode: Mode) -> u64 {
    let seconds = if mode == Mode::Conveyor {
        settings.conveyor.run_s + CONVEYOR_END_S
    } else {
        settings.gather.stream_max_s
    };
    (seconds / settings.period_s()).ceil() as u64
}

/// What a conveyor session gathers beyond its `conveyor.run_s`: the stop that brings it to
/// rest at its end, s.
pub const CONVEYOR_END_S: f64 = 5.0;

/// Cycles the loop holds the end of a path of `mode` with its loop closed
/// (`trajectory.settle_s`): none when homing, which settles every motor at home itself, or
/// checking, which rests after each pulse.
pub fn settle_cycles(settings: &Settings, mode: Mode) -> u64 {
    if mode == Mode::Home || mode == Mode::Check {
        0
    } else {
        (settings.trajectory.settle_s / settings.period_s()).round() as u64
    }
}

/// The plan of `mode` with `settings`: the limits of the settings, software limits only in a
/// homed frame (off when homing, checking or with `--unhomed`; the loop checks them only for
/// homed motors), homing required unless homing, jogging, checking or `--unhomed`, the
/// hwserver's switch latch off while homing or jogging (those generators watch the switches).
pub fn plan_for(settings: &Settings, mode: Mode, deterministic: bool, unhomed: bool) -> MovePlan {
    let homing = mode == Mode::Home;
    let mut limits = MoveLimits::none();
    let mut soft = [(f64::NEG_INFINITY, f64::INFINITY); MAX_MOTORS];
    for (m, s) in settings.safety.iter().enumerate().take(settings.n_motors) {
        soft[m] = (s.soft_limits[0], s.soft_limits[1]);
        limits.max_following_error[m] = s.max_following_error_counts;
        limits.max_integrated_error[m] = s.max_integrated_error_counts;
    }
    limits.soft = (!homing && !unhomed && mode != Mode::Check).then_some(soft);
    // Lock-step time is simulated: a host stall skips no sample there, so it is no overrun.
    limits.max_missed_in_row = if deterministic { u64::MAX } else { settings.max_missed_in_row };
    MovePlan {
        gather_every: settings.gather.every,
        gather_fields: settings.gather.fields,
        deterministic,
        starve_hold_cycles: (settings.trajectory.starve_hold_ms * 1e6 / settings.period_ns() as f64)
            .ceil() as u64,
        settle_cycles: settle_cycles(settings, mode),
        stream_gather_samples: stream_gather_samples(settings, mode),
        // A session serves as long as it is told: it keeps its last gather.stream_max_s.
        gather_keeps_last: mode == Mode::Serve,
        limits,
        require_homed: !homing && !unhomed && !matches!(mode, Mode::Jog | Mode::Check),
        // Homing and jog watch the switches themselves (a motor may rest on one).
        // A Cartesian jog is a line in the homed frame: the switches are watched.
        monitor_switches: !(homing || mode == Mode::Jog && settings.jog.axis.is_none()),
        gripper_mask: settings.s626.gripper_dio.map_or(0, |c| 1 << c),
        ..MovePlan::new(mode, settings.n_motors, settings.period_ns())
    }
}
