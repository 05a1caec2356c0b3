//! `[hwserver]` and `[safety]`: the link to the hardware server, its watchdog, and the timing
//! bounds whose defaults depend on the backend.

use crate::source::{S, Source, one_of, positive, span_of};
use crate::{ConfigLoadError, TimerSettings};
use serde::{Deserialize, Serialize};

/// The hardware the hwserver drives (`hwserver.backend`, `--backend`): a closed set, one
/// variant per entry of the hwserver's registry (`qmarc_hwserver::backends::BACKENDS`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// The simulated Deltabot.
    #[default]
    Sim,
    /// The Sensoray 626 through the kernel's comedi driver.
    S626,
}

impl BackendKind {
    /// Every backend, in the registry's order.
    pub const ALL: [BackendKind; 2] = [BackendKind::Sim, BackendKind::S626];
    /// Their names.
    pub const NAMES: [&'static str; 2] = ["sim", "s626"];

    /// Its name in the settings and on the command line.
    pub fn name(self) -> &'static str {
        BackendKind::NAMES[self as usize]
    }
}

impl std::str::FromStr for BackendKind {
    type Err = String;
    /// The backend named `v`; any other name is an error naming them all.
    fn from_str(v: &str) -> Result<BackendKind, String> {
        BackendKind::ALL.into_iter().find(|b| b.name() == v).ok_or_else(|| {
            format!("unknown backend `{v}`; available: {}", BackendKind::NAMES.join(", "))
        })
    }
}

impl std::fmt::Display for BackendKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The link to the hardware server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HwServerSettings {
    /// The hardware.
    pub backend: BackendKind,
    /// Controller silence, in periods, after which the hwserver disables everything.
    pub watchdog_periods: u32,
    /// A response later than this many periods makes the controller check whether the
    /// hwserver process is still alive.
    pub deadline_periods: u32,
    /// No response within this many periods means the hwserver is lost.
    pub response_timeout_periods: u32,
    /// Fastest an encoder can physically count, counts/s; a larger jump is an encoder fault.
    pub max_counts_per_s: f64,
    /// How the hwserver waits for a request: block on its event listener (the default), or
    /// busy-poll (a CPU of its own: pin it with `timer.hwserver_cpu`).
    pub wait: HwWait,
    /// The controller polls for each response this long before it blocks, µs (0: at once).
    pub response_spin_us: u32,
}

/// How the hwserver waits for the controller's requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HwWait {
    /// Block on the request event (no CPU used while waiting).
    #[default]
    Block,
    /// Busy-poll the request port: no wake-up to pay, a whole CPU used.
    Spin,
}

impl std::fmt::Display for HwWait {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            HwWait::Block => "block",
            HwWait::Spin => "spin",
        })
    }
}

impl std::str::FromStr for HwWait {
    type Err = String;
    fn from_str(s: &str) -> Result<HwWait, String> {
        match s {
            "block" => Ok(HwWait::Block),
            "spin" => Ok(HwWait::Spin),
            other => Err(format!("must be \"block\" or \"spin\", found \"{other}\"")),
        }
    }
}

impl Default for HwServerSettings {
    fn default() -> HwServerSettings {
        HwServerSettings {
            backend: BackendKind::Sim,
            watchdog_periods: TimingDefaults::SIMULATED.watchdog_periods,
            deadline_periods: 5,
            response_timeout_periods: 250,
            max_counts_per_s: 500_000.0,
            wait: HwWait::Block,
            response_spin_us: 0,
        }
    }
}

/// Timing bounds whose defaults depend on the backend. Real hardware keeps the tight bounds a
/// PREEMPT_RT machine meets (thesis 4.2; PMAC and Mesa watchdogs are a few periods). The
/// simulated robot runs on ordinary desktops and VMs, whose host stalls reach tens of ms
/// (`../shared/notes/realtime-linux.md`): nothing physical is at stake there, so its bounds
/// ride those out. A value set in the file holds for every backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimingDefaults {
    /// `hwserver.watchdog_periods`.
    pub watchdog_periods: u32,
    /// `safety.max_missed_in_row`.
    pub max_missed_in_row: u64,
}

impl TimingDefaults {
    /// On real hardware: 10 periods (4 ms at 400 µs) and 25 periods (10 ms).
    pub const HARDWARE: TimingDefaults =
        TimingDefaults { watchdog_periods: 10, max_missed_in_row: 25 };
    /// On the simulated robot: 250 periods (100 ms at 400 µs) for both.
    pub const SIMULATED: TimingDefaults =
        TimingDefaults { watchdog_periods: 250, max_missed_in_row: 250 };

    /// The defaults of `backend`.
    pub fn of(backend: BackendKind) -> TimingDefaults {
        match backend {
            BackendKind::Sim => TimingDefaults::SIMULATED,
            BackendKind::S626 => TimingDefaults::HARDWARE,
        }
    }
}

/// Which of the [`TimingDefaults`] the settings file set itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ExplicitTiming {
    /// `hwserver.watchdog_periods` is in the file.
    pub watchdog_periods: bool,
    /// `safety.max_missed_in_row` is in the file.
    pub max_missed_in_row: bool,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHwServer {
    backend: S<String>,
    watchdog_periods: S<i64>,
    deadline_periods: S<i64>,
    response_timeout_periods: S<i64>,
    max_counts_per_s: S<f64>,
    wait: S<String>,
    response_spin_us: S<i64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSafety {
    max_missed_in_row: S<i64>,
}

impl RawHwServer {
    /// Checked; the watchdog's default is the backend's.
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<HwServerSettings, ConfigLoadError> {
        let d = HwServerSettings::default();
        let backend = src.read(&self.backend, "hwserver.backend", d.backend, |v: &String| {
            one_of(&BackendKind::NAMES, "backend")(v)?;
            v.parse()
        })?;
        let watchdog = TimingDefaults::of(backend).watchdog_periods;
        let deadline_periods = src.int(
            &self.deadline_periods,
            "hwserver.deadline_periods",
            d.deadline_periods.into(),
            1,
            1_000_000,
        )?;
        Ok(HwServerSettings {
            watchdog_periods: src.int(
                &self.watchdog_periods,
                "hwserver.watchdog_periods",
                watchdog.into(),
                2,
                1_000_000,
            )? as u32,
            deadline_periods: deadline_periods as u32,
            response_timeout_periods: src.int(
                &self.response_timeout_periods,
                "hwserver.response_timeout_periods",
                d.response_timeout_periods.into(),
                deadline_periods,
                1_000_000,
            )? as u32,
            max_counts_per_s: src.take(
                &self.max_counts_per_s,
                "hwserver.max_counts_per_s",
                d.max_counts_per_s,
                positive,
            )?,
            wait: src.read(&self.wait, "hwserver.wait", d.wait, |v| v.parse())?,
            response_spin_us: src.int(
                &self.response_spin_us,
                "hwserver.response_spin_us",
                d.response_spin_us.into(),
                0,
                100_000,
            )? as u32,
            backend,
        })
    }

    /// A spinning hwserver needs a CPU of its own: pinned to the servo thread's CPU, at its
    /// higher priority, it would never let the servo thread run.
    pub(crate) fn check_spin_cpu(
        &self,
        src: &Source<'_>,
        hw: &HwServerSettings,
        timer: &TimerSettings,
    ) -> Result<(), ConfigLoadError> {
        match (hw.wait, timer.servo_cpu) {
            (HwWait::Spin, Some(cpu)) if timer.hwserver_cpu == Some(cpu) => Err(src.invalid(
                span_of(&self.wait),
                "hwserver.wait",
                format!(
                    "\"spin\" needs a CPU of its own, but timer.servo_cpu and \
                     timer.hwserver_cpu are both {cpu}: the spinning hwserver would starve the \
                     servo thread; pin them to different CPUs, or wait = \"block\" (one CPU \
                     shared by both is fast when they block: BENCHMARKS.md)"
                ),
            )),
            _ => Ok(()),
        }
    }

    /// Whether the file sets the watchdog.
    pub(crate) fn sets_watchdog(&self) -> bool {
        self.watchdog_periods.is_some()
    }
}

impl RawSafety {
    /// `safety.max_missed_in_row`, its default the backend's.
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        backend: BackendKind,
    ) -> Result<u64, ConfigLoadError> {
        let d = TimingDefaults::of(backend).max_missed_in_row as i64;
        Ok(src.int(&self.max_missed_in_row, "safety.max_missed_in_row", d, 1, 1_000_000)? as u64)
    }

    /// Whether the file sets it.
    pub(crate) fn sets_max_missed(&self) -> bool {
        self.max_missed_in_row.is_some()
    }
}
