//! [`HwServerArgs`]: the hwserver's command line. The starter builds it from the settings
//! file and passes it with [`HwServerArgs::to_args`]; run by hand, the defaults are the
//! simulated Deltabot of `../shared/notes/deltabot.md`.

use crate::sim::{SimParams, SimParamsError};
use clap::{Parser, ValueEnum};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};

/// Which hardware to drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Default)]
pub enum BackendKind {
    /// The simulated Deltabot.
    #[default]
    Sim,
}

/// Command line of `qmarc-hwserver`.
#[derive(Debug, Clone, PartialEq, Parser)]
#[command(
    name = "qmarc-hwserver",
    version,
    about = "QMARC hardware server (started by qmarc-starter)"
)]
pub struct HwServerArgs {
    /// Prefix of every iceoryx2 file of this run.
    #[arg(long, default_value = "qmarc_")]
    pub iox_prefix: String,
    /// iceoryx2 root directory.
    #[arg(long, default_value = DEFAULT_ROOT)]
    pub iox_root: String,
    /// Hardware backend.
    #[arg(long, value_enum, default_value_t = BackendKind::Sim)]
    pub backend: BackendKind,
    /// Number of motors.
    #[arg(long, default_value_t = 3)]
    pub motors: usize,
    /// Servo period in µs (the watchdog's unit and the simulator's lock-step).
    #[arg(long, default_value_t = 400)]
    pub period_us: u64,
    /// Lock-step simulated clock: exactly one period per read, reproducible data.
    #[arg(long)]
    pub deterministic: bool,
    /// Silence from the controller, in periods, after which enabled motors are disabled and
    /// the server exits.
    #[arg(long, default_value_t = 10)]
    pub watchdog_periods: u32,
    /// Fastest a counter can physically change, counts/s: a larger jump between two reads is
    /// an encoder fault.
    #[arg(long, default_value_t = 500_000.0)]
    pub max_counts_per_s: f64,
    /// SCHED_FIFO priority of the server (above the controller's); 0 runs SCHED_OTHER.
    #[arg(long, default_value_t = 85)]
    pub priority: i32,
    /// Do not lock memory.
    #[arg(long)]
    pub no_mlock: bool,
    /// Busy-poll for requests instead of blocking (only on an isolated core).
    #[arg(long)]
    pub spin: bool,
    /// Simulator: amplifier gain, counts/s per volt.
    #[arg(long, default_value_t = 25_000.0)]
    pub sim_kv: f64,
    /// Simulator: velocity lag of an enabled amplifier, s.
    #[arg(long, default_value_t = 0.004)]
    pub sim_tau_s: f64,
    /// Simulator: coasting time constant of a disabled motor, s.
    #[arg(long, default_value_t = 0.05)]
    pub sim_coast_tau_s: f64,
    /// Simulator: start position per motor, counts (comma-separated; missing motors start at 0).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub sim_start: Vec<f64>,
    /// Simulator: top limit switch position, counts.
    #[arg(long, default_value_t = -9_500.0, allow_negative_numbers = true)]
    pub sim_top_switch: f64,
    /// Simulator: bottom limit switch position, counts.
    #[arg(long, default_value_t = 10_500.0, allow_negative_numbers = true)]
    pub sim_bottom_switch: f64,
    /// Simulator: start unhomed, the counters `--sim-counter-offset` counts off the homed frame.
    #[arg(long)]
    pub sim_unhomed: bool,
    /// Simulator: offset of an unhomed counter frame, counts.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub sim_counter_offset: i64,
    /// Simulator fault injection: this motor (1-based) does not move.
    #[arg(long)]
    pub sim_stall: Option<usize>,
    /// Simulator fault injection: this motor's (1-based) top switch sticks once tripped.
    #[arg(long)]
    pub sim_stuck_top: Option<usize>,
    /// Simulator: write its event log (switch edges, amplifier changes, last access; simulated
    /// clock) to this file when the server ends.
    #[arg(long)]
    pub sim_events: Option<std::path::PathBuf>,
    /// Simulator: keep the homed frame between runs in this file (a tmpfs file: a reboot
    /// clears it, as a power cycle clears the card's counters).
    #[arg(long)]
    pub sim_state: Option<std::path::PathBuf>,
}

impl Default for HwServerArgs {
    fn default() -> HwServerArgs {
        HwServerArgs::parse_from(["qmarc-hwserver"])
    }
}

impl HwServerArgs {
    /// The arguments that make `qmarc-hwserver` parse back exactly `self`.
    pub fn to_args(&self) -> Vec<String> {
        let mut a = vec![
            format!("--iox-prefix={}", self.iox_prefix),
            format!("--iox-root={}", self.iox_root),
            format!(
                "--backend={}",
                self.backend.to_possible_value().map_or("sim".into(), |v| v.get_name().to_string())
            ),
            format!("--motors={}", self.motors),
            format!("--period-us={}", self.period_us),
            format!("--watchdog-periods={}", self.watchdog_periods),
            format!("--max-counts-per-s={}", self.max_counts_per_s),
            format!("--priority={}", self.priority),
            format!("--sim-kv={}", self.sim_kv),
            format!("--sim-tau-s={}", self.sim_tau_s),
            format!("--sim-coast-tau-s={}", self.sim_coast_tau_s),
            format!("--sim-top-switch={}", self.sim_top_switch),
            format!("--sim-bottom-switch={}", self.sim_bottom_switch),
        ];
        if self.sim_unhomed {
            a.push("--sim-unhomed".into());
        }
        if self.sim_counter_offset != 0 {
            a.push(format!("--sim-counter-offset={}", self.sim_counter_offset));
        }
        if let Some(m) = self.sim_stall {
            a.push(format!("--sim-stall={m}"));
        }
        if let Some(m) = self.sim_stuck_top {
            a.push(format!("--sim-stuck-top={m}"));
        }
        if let Some(p) = &self.sim_events {
            a.push(format!("--sim-events={}", p.display()));
        }
        if let Some(p) = &self.sim_state {
            a.push(format!("--sim-state={}", p.display()));
        }
        if !self.sim_start.is_empty() {
            let list: Vec<String> = self.sim_start.iter().map(f64::to_string).collect();
            a.push(format!("--sim-start={}", list.join(",")));
        }
        for (on, flag) in [
            (self.deterministic, "--deterministic"),
            (self.no_mlock, "--no-mlock"),
            (self.spin, "--spin"),
        ] {
            if on {
                a.push(flag.to_string());
            }
        }
        a
    }

    /// Where the iceoryx2 files live (checked: see [`IpcLocation::checked`]).
    pub fn location(&self) -> Result<IpcLocation, String> {
        IpcLocation::checked(&self.iox_prefix, &self.iox_root)
    }

    /// The servo period in ns.
    pub fn period_ns(&self) -> u64 {
        self.period_us * 1_000
    }

    /// The simulator parameters, checked.
    pub fn sim_params(&self) -> Result<SimParams, SimParamsError> {
        if self.sim_start.len() > MAX_MOTORS {
            return Err(SimParamsError::OutOfRange {
                name: "sim-start",
                value: self.sim_start.len() as f64,
                expected: "at most 4 positions",
            });
        }
        let mut start_counts = [0.0; MAX_MOTORS];
        start_counts[..self.sim_start.len()].copy_from_slice(&self.sim_start);
        let p = SimParams {
            n_motors: self.motors,
            period_ns: self.period_ns(),
            lockstep: self.deterministic,
            kv_counts_per_s_per_v: self.sim_kv,
            tau_s: self.sim_tau_s,
            coast_tau_s: self.sim_coast_tau_s,
            start_counts,
            top_switch_counts: self.sim_top_switch,
            bottom_switch_counts: self.sim_bottom_switch,
            homed: !self.sim_unhomed,
            counter_offset: self.sim_counter_offset,
            stall_motor: self.sim_stall.map(|m| m.wrapping_sub(1)),
            stuck_top_motor: self.sim_stuck_top.map(|m| m.wrapping_sub(1)),
        };
        p.validate()?;
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn to_args_parses_back_to_the_same_arguments() {
        let mut a = HwServerArgs::default();
        assert_eq!(
            HwServerArgs::parse_from(std::iter::once("x".to_string()).chain(a.to_args())),
            a
        );
        a.iox_prefix = "t_1_".into();
        a.motors = 2;
        a.deterministic = true;
        a.spin = true;
        a.sim_start = vec![-12.5, 3e6];
        a.sim_top_switch = 200.0;
        a.sim_bottom_switch = -0.25;
        a.sim_unhomed = true;
        a.sim_counter_offset = -123;
        a.sim_stall = Some(2);
        a.sim_stuck_top = Some(1);
        a.sim_events = Some("/tmp/e.csv".into());
        a.sim_state = Some("/dev/shm/s".into());
        let back = HwServerArgs::parse_from(std::iter::once("x".to_string()).chain(a.to_args()));
        assert_eq!(back, a);
        let p = back.sim_params().unwrap();
        assert_eq!(p.start_counts, [-12.5, 3e6, 0.0, 0.0]);
        assert!(p.lockstep);
        assert_eq!(
            (p.homed, p.counter_offset, p.stall_motor, p.stuck_top_motor),
            (false, -123, Some(1), Some(0))
        );
    }

    #[test]
    fn defaults_are_the_notes_plant() {
        let p = HwServerArgs::default().sim_params().unwrap();
        let d = SimParams::default();
        assert_eq!(p, d);
    }
}
