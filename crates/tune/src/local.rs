//! [`run_local`]: a lock-step move on the simulated robot inside this process, unpaced.
//!
//! The very code of a move of the process set — the registry's generator and law in the
//! controller's `Servo`, the hwserver's [`HwCore`] around the simulated Deltabot — with the
//! iceoryx2 exchange replaced by a call: the core ([`open_core`]) is the link and answers
//! each request in place. Time is the simulator's and nothing waits for the timer, so a move
//! takes only its computing time, and its data are byte for byte those of
//! `qmarc-starter --deterministic` (the tests compare them). Tuning evaluates its candidates
//! this way.

use qmarc_config::{Mode, RunSpec};
use qmarc_controller::record::MoveRecord;
use qmarc_controller_process::run::{RunError, build_servo};
use qmarc_hwserver::HwCore;
use qmarc_hwserver::backend::BackendOpenError;
use qmarc_proto::link::HwLink;
use qmarc_proto::{HwMsg, MsgType};
use qmarc_report::Summary;
use qmarc_timer::UnpacedTicker;
use qmarc_timer::rt::RtStatus;
use std::sync::atomic::AtomicBool;

/// The hwserver's core of the settings' simulated robot, in lock-step: the link of a local
/// move (the core answers each request in place of the iceoryx2 exchange).
pub fn open_core(spec: &RunSpec) -> Result<HwCore, LocalError> {
    let s = &spec.settings;
    if s.hwserver.backend != qmarc_config::BackendKind::Sim {
        return Err(LocalError::NotSim(s.hwserver.backend));
    }
    let backend = qmarc_hwserver::backends::open(s, true)?;
    Ok(HwCore::for_settings(backend, s))
}

/// A local move could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LocalError {
    /// Only the simulated robot runs in lock-step.
    #[error("a move inside this process runs only on the simulated robot, not on `{0}`")]
    NotSim(qmarc_config::BackendKind),
    /// Homing presets the counters between moves: run it through the process set.
    #[error("homing is not run inside this process: `qmarc-starter home`")]
    Homing,
    /// The simulated robot could not be opened.
    #[error(transparent)]
    Backend(#[from] BackendOpenError),
    /// The move could not be built or could not start.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The simulator's files could not be written when it ended.
    #[error("the simulated robot's files: {0}")]
    Finish(std::io::Error),
}

/// The run of a local move of `mode` with `settings`: lock-step, unpaced, no iceoryx2.
pub fn local_spec(settings: qmarc_config::Settings, mode: Mode) -> RunSpec {
    RunSpec {
        settings,
        mode,
        deterministic: true,
        unpaced: true,
        unhomed: false,
        iox_prefix: String::new(),
        iox_root: String::new(),
        epoch_ns: 0,
    }
}

/// A move made by [`run_local`]: the loop with its gathered data, and its summary.
pub struct LocalMove {
    /// What the move left (its gathered rows, its error figures).
    pub record: MoveRecord,
    /// What `summary.json` would say.
    pub summary: Summary,
}

/// Runs the move `spec` in lock-step on the simulated robot inside this process, as fast as
/// it computes. `stop` ends it early as a stop signal would (motors disabled, the fault
/// `aborted`). A fault is a result: it is in the summary.
pub fn run_local(spec: &RunSpec, stop: &AtomicBool) -> Result<LocalMove, LocalError> {
    if spec.mode == Mode::Home {
        return Err(LocalError::Homing);
    }
    let spec = RunSpec { deterministic: true, unpaced: true, ..spec.clone() };
    let mut core = open_core(&spec)?;
    let mut servo = build_servo(&spec, None)?;
    let mut ticker = UnpacedTicker::new(spec.settings.period_ns());
    let moved = servo.run(&mut core, &mut ticker, stop);
    // The thesis' last message, as the controller sends it: the hardware is made safe.
    let _ = core.exchange(&HwMsg::request(MsgType::Exit));
    core.finish().map_err(LocalError::Finish)?;
    moved.map_err(RunError::from)?;
    let record = servo.into_record();
    let summary = qmarc_report::summarize::summarize(
        &spec.settings,
        &record,
        &RtStatus {
            requested_priority: None,
            fifo_priority: None,
            memory_locked: false,
            warnings: Vec::new(),
        },
        spec.mode,
        true,
    );
    Ok(LocalMove { record, summary })
}

/// The first and the last command of the path of `settings` (`trajectory.knots` with its
/// method), counts per motor: where the robot must stand for it to start, and where it ends.
pub fn path_ends(settings: &qmarc_config::Settings) -> Result<(Vec<f64>, Vec<f64>), String> {
    let method = &settings.trajectory.method;
    let entry = qmarc_plugins::registry::generator(method)
        .ok_or_else(|| format!("no trajectory generator `{method}`"))?;
    let mut s = settings.clone();
    s.trajectory.start_tolerance_counts = f64::INFINITY;
    let mut generator = (entry.build)(&s).map_err(|e| e.to_string())?;
    generator.start(&[0.0; qmarc_proto::MAX_MOTORS]).map_err(|e| e.to_string())?;
    let (mut first, mut last) = ([0.0; qmarc_proto::MAX_MOTORS], [0.0; qmarc_proto::MAX_MOTORS]);
    generator.sample(0, &mut first);
    let samples = generator.samples().ok_or("tuning needs a knot file, not a stream")?;
    generator.sample(samples.saturating_sub(1), &mut last);
    let n = settings.n_motors;
    Ok((first[..n].to_vec(), last[..n].to_vec()))
}

/// `settings` with the simulated robot standing homed at the start of its path and no kept
/// frame read or written (`sim.state_file` off): tuning's moves all start there.
pub fn on_the_path(settings: &qmarc_config::Settings) -> Result<qmarc_config::Settings, String> {
    let mut s = settings.clone();
    s.sim.start_counts = path_ends(settings)?.0;
    s.sim.plant.homed = true;
    s.sim.state_file = None;
    Ok(s)
}
