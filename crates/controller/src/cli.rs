//! The command line shared by `qmarc-starter` and `qmarc-controller`: the starter parses it,
//! checks it, and hands the controller the same options with [`MoveOptions::to_args`] and
//! [`Mode::to_args`].

use crate::config::{ConfigLoadError, Settings};
use clap::{Args, Subcommand};
use std::path::PathBuf;

/// Parses the command line of a QMARC program. A wrong command line prints clap's message and
/// exits with [`qmarc_proto::exit::USAGE`] (clap's own code, 2, would read as "fault"); `--help`
/// and `--version` print and exit 0.
pub fn parse_or_exit<T: clap::Parser>() -> T {
    match T::try_parse() {
        Ok(t) => t,
        Err(e) => {
            let code =
                if e.use_stderr() { qmarc_proto::exit::USAGE } else { qmarc_proto::exit::OK };
            let _ = e.print();
            std::process::exit(i32::from(code));
        }
    }
}

/// Options of every move; flags override the settings file for this run. They are global:
/// they go before or after the subcommand (`qmarc-starter --out x step` or
/// `qmarc-starter step --out x`).
#[derive(Debug, Clone, PartialEq, Args)]
pub struct MoveOptions {
    /// Settings file.
    #[arg(long, global = true, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory for gather.csv, gather.m and summary.json (default: `gather.out_dir`).
    #[arg(long, global = true)]
    pub out: Option<PathBuf>,
    /// Gather every N-th servo cycle (default: `gather.every`).
    #[arg(long, global = true)]
    pub gather_every: Option<u32>,
    /// Servo period in µs (default: `general.period_us`).
    #[arg(long, global = true)]
    pub period_us: Option<u32>,
    /// Number of motors (default: `general.n_motors`; each needs its `[[motor]]` table).
    #[arg(long, global = true)]
    pub motors: Option<usize>,
    /// Lock-step simulated clock: two runs produce byte-identical data files.
    #[arg(long, global = true)]
    pub deterministic: bool,
    /// Move although the frame is not homed; software position limits are then off.
    #[arg(long, global = true)]
    pub unhomed: bool,
    /// Hardware backend (default: `hwserver.backend`): `sim`, the simulated Deltabot.
    #[arg(long, global = true)]
    pub backend: Option<String>,
}

impl MoveOptions {
    /// Loads the settings file and applies the overrides.
    pub fn load(&self) -> Result<Settings, ConfigLoadError> {
        let mut s = Settings::load(&self.config)?;
        if let Some(p) = self.period_us {
            s.set_period_us(p)?;
        }
        if let Some(n) = self.gather_every {
            s.set_gather_every(n)?;
        }
        if let Some(n) = self.motors {
            s.set_n_motors(n)?;
        }
        if let Some(out) = &self.out {
            s.gather.out_dir = out.clone();
        }
        if let Some(b) = &self.backend {
            s.set_backend(b)?;
        }
        Ok(s)
    }

    /// The same options as arguments.
    pub fn to_args(&self) -> Vec<String> {
        let mut a = vec![format!("--config={}", self.config.display())];
        if let Some(out) = &self.out {
            a.push(format!("--out={}", out.display()));
        }
        if let Some(n) = self.gather_every {
            a.push(format!("--gather-every={n}"));
        }
        if let Some(p) = self.period_us {
            a.push(format!("--period-us={p}"));
        }
        if let Some(n) = self.motors {
            a.push(format!("--motors={n}"));
        }
        if self.deterministic {
            a.push("--deterministic".into());
        }
        if self.unhomed {
            a.push("--unhomed".into());
        }
        if let Some(b) = &self.backend {
            a.push(format!("--backend={b}"));
        }
        a
    }
}

/// What to do.
#[derive(Debug, Clone, PartialEq, Subcommand)]
pub enum Mode {
    /// Step every motor by `--size` counts and hold for `--duration` s (tuning, thesis 3.4).
    Step(StepArgs),
    /// Run a path from a knot file or stream (thesis 3.12, A.2.3).
    Run(RunArgs),
    /// Home the robot on its top limit switches, one motor at a time (thesis 3.10.1.1).
    Home,
}

/// Options of `run`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct RunArgs {
    /// Knot file, or `-` for standard input (default: `trajectory.knots`).
    #[arg(long)]
    pub knots: Option<PathBuf>,
    /// `spline` (offline cubic spline), `pvt` (online PVT) or `step` (default:
    /// `trajectory.method`).
    #[arg(long)]
    pub method: Option<String>,
}

/// Options of `step`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct StepArgs {
    /// Step size in counts (default: `step.size`).
    #[arg(long, allow_negative_numbers = true)]
    pub size: Option<i64>,
    /// Duration in s (default: `step.duration_s`).
    #[arg(long)]
    pub duration: Option<f64>,
}

impl Mode {
    /// The mode's name (`step`, `run`).
    pub fn name(&self) -> &'static str {
        match self {
            Mode::Step(_) => "step",
            Mode::Run(_) => "run",
            Mode::Home => "home",
        }
    }

    /// The registered generator the mode uses with settings `s` (after [`Mode::apply`]).
    pub fn generator<'a>(&self, s: &'a Settings) -> &'a str {
        match self {
            Mode::Step(_) => "step",
            Mode::Run(_) => &s.trajectory.method,
            Mode::Home => "home",
        }
    }

    /// Applies the mode's overrides to `s`.
    pub fn apply(&self, s: &mut Settings) -> Result<(), ConfigLoadError> {
        match self {
            Mode::Step(a) => {
                if let Some(size) = a.size {
                    s.set_step_size(size)?;
                }
                if let Some(d) = a.duration {
                    s.set_step_duration(d)?;
                }
            }
            Mode::Run(a) => {
                if let Some(k) = &a.knots {
                    s.set_knots(k);
                }
                if let Some(m) = &a.method {
                    s.set_method(m)?;
                }
            }
            Mode::Home => {}
        }
        Ok(())
    }

    /// The mode as arguments (subcommand first).
    pub fn to_args(&self) -> Vec<String> {
        match self {
            Mode::Step(a) => {
                let mut v = vec!["step".to_string()];
                if let Some(size) = a.size {
                    v.push(format!("--size={size}"));
                }
                if let Some(d) = a.duration {
                    v.push(format!("--duration={d}"));
                }
                v
            }
            Mode::Run(a) => {
                let mut v = vec!["run".to_string()];
                if let Some(k) = &a.knots {
                    v.push(format!("--knots={}", k.display()));
                }
                if let Some(m) = &a.method {
                    v.push(format!("--method={m}"));
                }
                v
            }
            Mode::Home => vec!["home".to_string()],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct T {
        #[command(flatten)]
        opts: MoveOptions,
        #[command(subcommand)]
        mode: Mode,
    }

    #[test]
    fn arguments_round_trip() {
        let t = T::parse_from([
            "x",
            "--out",
            "/tmp/o",
            "--gather-every",
            "4",
            "--period-us",
            "500",
            "--deterministic",
            "step",
            "--size",
            "-250",
            "--duration",
            "0.75",
        ]);
        let args: Vec<String> = std::iter::once("x".to_string())
            .chain(t.opts.to_args())
            .chain(t.mode.to_args())
            .collect();
        let back = T::parse_from(args);
        assert_eq!(back.opts, t.opts);
        assert_eq!(back.mode, t.mode);
        assert_eq!(back.mode, Mode::Step(StepArgs { size: Some(-250), duration: Some(0.75) }));
        let t = T::parse_from(["x", "--motors", "2", "run", "--knots", "-", "--method", "pvt"]);
        let args: Vec<String> = std::iter::once("x".to_string())
            .chain(t.opts.to_args())
            .chain(t.mode.to_args())
            .collect();
        let back = T::parse_from(args);
        assert_eq!((back.opts.motors, &back.mode), (Some(2), &t.mode));
    }
}
