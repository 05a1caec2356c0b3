//! `[sim]`: the simulated Deltabot (`../shared/notes/deltabot.md`; the geometry is an
//! assumption) and its fault injection.

use crate::ConfigLoadError;
use crate::source::{S, Source, finite, positive, span_of};
use qmarc_proto::MAX_MOTORS;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where the simulated robot keeps its homed frame between runs by default: on the tmpfs
/// `/dev/shm`, which a reboot clears.
pub const DEFAULT_SIM_STATE_FILE: &str = "/dev/shm/qmarc-sim.state";

/// The simulated Deltabot's plant, switches, frame and fault injection: the numbers the
/// simulator runs on, one definition for the settings (`[sim]`) and the simulator's own
/// parameters (`qmarc_hwserver::SimParams`). Motors are 1-based here and everywhere they are
/// named, as the user counts them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimPlant {
    /// Amplifier gain, counts/s per volt.
    pub kv: f64,
    /// Velocity lag of an enabled amplifier, s (a first-order loop: when
    /// `velocity_loop_hz` is 0).
    pub tau_s: f64,
    /// Natural frequency of the amplifier's velocity loop, Hz (second order); 0: the
    /// first-order lag `tau_s` instead.
    pub velocity_loop_hz: f64,
    /// Damping ratio of that velocity loop (underdamped: 0.05‥0.99).
    pub velocity_loop_zeta: f64,
    /// Coasting time constant of a disabled motor, s.
    pub coast_tau_s: f64,
    /// Top limit switch position, counts in the homed frame (reached moving away from the
    /// bottom switch).
    pub top_switch_counts: f64,
    /// Bottom limit switch position, counts in the homed frame.
    pub bottom_switch_counts: f64,
    /// The robot starts in the homed frame (its counters "kept counting since the last
    /// homing"); false: the counters start `counter_offset` counts away from it.
    pub homed: bool,
    /// Offset of an unhomed counter frame, counts.
    pub counter_offset: i64,
    /// Fault injection: this motor (1-based) does not move, whatever it is told (a seized
    /// joint, a broken coupling).
    pub stall_motor: Option<usize>,
    /// Fault injection: this motor's (1-based) top switch sticks once tripped.
    pub stuck_top_motor: Option<usize>,
    /// Fault injection: this motor (1-based) moves against its command (an amplifier wired
    /// the other way round; also the plant of `--device fake`).
    #[serde(default)]
    pub reversed_motor: Option<usize>,
    /// Fault injection: the emergency-stop chain is open from the first to the second time,
    /// s of the simulator's clock since the hwserver started (a button pressed, then
    /// released); `None`: never.
    #[serde(default)]
    pub estop_open_s: Option<[f64; 2]>,
}

impl SimPlant {
    /// Whether the fault-injection motor `which` (1-based) is motor `m` (0-based).
    pub fn is(which: Option<usize>, m: usize) -> bool {
        which == Some(m + 1)
    }
}

impl Default for SimPlant {
    fn default() -> SimPlant {
        SimPlant {
            kv: 23_650.0,
            tau_s: 0.004,
            velocity_loop_hz: 61.6,
            velocity_loop_zeta: 0.48,
            coast_tau_s: 0.05,
            top_switch_counts: -9_500.0,
            bottom_switch_counts: 10_500.0,
            homed: true,
            counter_offset: 0,
            stall_motor: None,
            stuck_top_motor: None,
            reversed_motor: None,
            estop_open_s: None,
        }
    }
}

/// The simulated Deltabot: its plant, where its motors start, and its files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimSettings {
    /// The plant, switches, frame and fault injection.
    #[serde(flatten)]
    pub plant: SimPlant,
    /// Start position per motor, counts (motors beyond the list start at 0).
    pub start_counts: Vec<f64>,
    /// Where the simulator writes its event log when it ends.
    pub events_file: Option<PathBuf>,
    /// Where the simulator keeps its homed frame between runs; `None`: nowhere.
    pub state_file: Option<PathBuf>,
}

impl Default for SimSettings {
    fn default() -> SimSettings {
        SimSettings {
            plant: SimPlant::default(),
            start_counts: Vec::new(),
            events_file: None,
            state_file: Some(PathBuf::from(DEFAULT_SIM_STATE_FILE)),
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSim {
    kv: S<f64>,
    tau_s: S<f64>,
    velocity_loop_hz: S<f64>,
    velocity_loop_zeta: S<f64>,
    coast_tau_s: S<f64>,
    start_counts: S<Vec<f64>>,
    top_switch_counts: S<f64>,
    bottom_switch_counts: S<f64>,
    homed: S<bool>,
    counter_offset: S<i64>,
    stall_motor: S<i64>,
    stuck_top_motor: S<i64>,
    reversed_motor: S<i64>,
    estop_open_s: S<Vec<f64>>,
    events_file: S<String>,
    state_file: S<String>,
}

/// A path setting: `""` means none.
fn path_or_none(p: String) -> Option<PathBuf> {
    (!p.is_empty()).then(|| PathBuf::from(p))
}

impl RawSim {
    /// Checked for `n_motors` motors (the fault-injection motors must be among them).
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        n_motors: usize,
    ) -> Result<SimSettings, ConfigLoadError> {
        let (d, files) = (SimPlant::default(), SimSettings::default());
        let motor = |v: &S<i64>, field: &str| -> Result<Option<usize>, ConfigLoadError> {
            let m = src.int(v, field, 0, 0, n_motors as i64)?;
            Ok((m > 0).then_some(m as usize))
        };
        let path = |v: &S<String>, field: &str, default: Option<PathBuf>| {
            let d = default.map_or(String::new(), |p| p.display().to_string());
            src.take(v, field, d, |_| Ok(())).map(path_or_none)
        };
        let plant = SimPlant {
            kv: src.take(&self.kv, "sim.kv", d.kv, positive)?,
            tau_s: src.take(&self.tau_s, "sim.tau_s", d.tau_s, positive)?,
            velocity_loop_hz: src.take(
                &self.velocity_loop_hz,
                "sim.velocity_loop_hz",
                d.velocity_loop_hz,
                |v| {
                    if v.is_finite() && (*v == 0.0 || (1.0..=1000.0).contains(v)) {
                        Ok(())
                    } else {
                        Err(format!(
                            "must be 0 (a first-order lag) or 1‥1000 Hz, found {}",
                            crate::num(*v)
                        ))
                    }
                },
            )?,
            velocity_loop_zeta: src.take(
                &self.velocity_loop_zeta,
                "sim.velocity_loop_zeta",
                d.velocity_loop_zeta,
                |v| {
                    if v.is_finite() && (0.05..=0.99).contains(v) {
                        Ok(())
                    } else {
                        Err(format!(
                            "must be 0.05‥0.99 (a velocity loop that rings), found {}",
                            crate::num(*v)
                        ))
                    }
                },
            )?,
            coast_tau_s: src.take(&self.coast_tau_s, "sim.coast_tau_s", d.coast_tau_s, positive)?,
            top_switch_counts: src.take(
                &self.top_switch_counts,
                "sim.top_switch_counts",
                d.top_switch_counts,
                finite,
            )?,
            bottom_switch_counts: src.take(
                &self.bottom_switch_counts,
                "sim.bottom_switch_counts",
                d.bottom_switch_counts,
                finite,
            )?,
            homed: src.take(&self.homed, "sim.homed", d.homed, |_| Ok(()))?,
            counter_offset: src.int(
                &self.counter_offset,
                "sim.counter_offset",
                d.counter_offset,
                -(1 << 23),
                1 << 23,
            )?,
            stall_motor: motor(&self.stall_motor, "sim.stall_motor")?,
            stuck_top_motor: motor(&self.stuck_top_motor, "sim.stuck_top_motor")?,
            reversed_motor: motor(&self.reversed_motor, "sim.reversed_motor")?,
            estop_open_s: src
                .take(&self.estop_open_s, "sim.estop_open_s", Vec::new(), |v| match v.as_slice() {
                    [] => Ok(()),
                    [from, to] if *from >= 0.0 && to > from && to.is_finite() => Ok(()),
                    _ => Err(format!(
                        "must be [] (never) or [from_s, to_s] with 0 ≤ from_s < to_s, finite \
                         (1e9 for ever), found {v:?}"
                    )),
                })?
                .try_into()
                .ok(),
        };
        let sim = SimSettings {
            plant,
            start_counts: src.take(
                &self.start_counts,
                "sim.start_counts",
                files.start_counts,
                |v| {
                    if v.len() > MAX_MOTORS {
                        return Err(format!("at most {MAX_MOTORS} positions, found {}", v.len()));
                    }
                    match v.iter().find(|x| !(x.is_finite() && x.abs() < f64::from(1u32 << 23))) {
                        Some(bad) => Err(format!(
                            "positions must be finite and within ±2^23 counts, found {bad}"
                        )),
                        None => Ok(()),
                    }
                },
            )?,
            events_file: path(&self.events_file, "sim.events_file", files.events_file)?,
            state_file: path(&self.state_file, "sim.state_file", files.state_file)?,
        };
        if plant.top_switch_counts == plant.bottom_switch_counts {
            return Err(src.invalid(
                span_of(&self.bottom_switch_counts),
                "sim.bottom_switch_counts",
                "must differ from sim.top_switch_counts",
            ));
        }
        Ok(sim)
    }
}
