//! `qmarc-bench jitter`: the servo pipeline's timing against a bare timer loop's, in
//! interleaved rounds inside one run (`../shared/notes/realtime-linux.md`: back-to-back runs of
//! identical code differ by up to 3.5× at p99.9, so only same-run ratios mean anything).
//!
//! - The bare loop: a thread with the servo thread's real-time request (SCHED_FIFO priority,
//!   `mlockall`, pre-faulted stack, `/dev/cpu_dma_latency` = 0) waiting on the controller's
//!   own [`Ticker`](qmarc_timer::Ticker), recording each wake with the loop's own
//!   [`TimingStats`] — cyclictest's algorithm, no IPC, no math.
//! - With `--bare-work-us W`, the same loop kept busy W µs after each wake: a VM's vCPU is
//!   taken away more often while it computes than while it sleeps, so a loop that works
//!   misses periods a sleeping one does not, whatever the work is.
//! - The servo pipeline: `qmarc-starter step` on the simulated robot (starter, hwserver and
//!   controller processes over iceoryx2) for the same time; its `summary.json` has the same
//!   figures, plus the output latency (tick → DAC write acknowledged).
//! - With several timers (`--timer both|all`), each round runs every timer's segments in
//!   turn, so the timers meet the same hour of the host, whose stalls decide the totals.

use crate::stats::{cv, median};
use anyhow::{Context, bail};
use qmarc_config::TimerMethod;
use qmarc_controller::stats::TimingStats;
use qmarc_report::Summary;
use qmarc_report::summary::Pct;
use qmarc_timer::TickerKind;
use qmarc_timer::clock::monotonic_now_ns;
use qmarc_timer::rt::{DmaLatencyGuard, RtRequest};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;

mod table;

/// Options of `jitter`.
#[derive(Debug, clap::Args)]
pub struct JitterArgs {
    /// Servo period, µs.
    #[arg(long, default_value_t = 400)]
    pub period_us: u32,
    /// Interleaved rounds (each one bare and one servo segment).
    #[arg(long, default_value_t = 5)]
    pub rounds: u32,
    /// Length of each segment, s.
    #[arg(long, default_value_t = 10.0)]
    pub segment_s: f64,
    /// The timer: `timerfd`, `nanosleep`, `timerfd-periodic`, `both` (timerfd and nanosleep)
    /// or `all` (default: the settings' `timer.method`); several take turns within each round.
    #[arg(long)]
    pub timer: Option<String>,
    /// Write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Settings file of the servo segments (and the bare loop's priority and memory lock).
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory holding qmarc-starter and its children (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Bare loop run and discarded before the rounds, s.
    #[arg(long, default_value_t = 2.0)]
    pub warmup_s: f64,
    /// The servo segments' hwserver busy-polls for requests and the controller polls for
    /// each response up to one period before blocking (`hwserver.wait = "spin"`,
    /// `hwserver.response_spin_us`): for a machine with a CPU to spare.
    #[arg(long)]
    pub spin: bool,
    /// Pin the servo thread and the bare loop to CPU 0 and the hwserver to CPU 1 (`--pin`,
    /// `split`) or to CPU 0 as well (`--pin=same`: one CPU shared by the blocking pair, whose
    /// exchange is then a local hand-over) (`timer.servo_cpu`, `timer.hwserver_cpu`).
    #[arg(long, num_args = 0..=1, default_missing_value = "split", value_enum)]
    pub pin: Option<Pin>,
    /// Also run, in each round, the bare loop kept busy this many µs after each wake (a
    /// servo cycle's length: its tick → DAC written p50 less its wake p50): the missed periods
    /// this machine allows a loop that works as long as ours does, IPC and math apart.
    #[arg(long)]
    pub bare_work_us: Option<u32>,
}

/// Where `--pin` puts the hwserver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Pin {
    /// The hwserver on CPU 1, the servo thread on CPU 0.
    Split,
    /// Both on CPU 0.
    Same,
}

impl Pin {
    /// The hwserver's CPU (the servo thread's is 0).
    fn hwserver_cpu(self) -> i64 {
        match self {
            Pin::Split => 1,
            Pin::Same => 0,
        }
    }

    /// What the table's heading says.
    fn describe(self) -> &'static str {
        match self {
            Pin::Split => ", servo and bare loop on CPU 0, hwserver on CPU 1",
            Pin::Same => ", servo, hwserver and bare loop on CPU 0, the rest of ours off it",
        }
    }
}

/// The settings the servo segments run with: `--config`, with `--spin` and `--pin` applied
/// to a copy in `scratch`.
fn segment_config(a: &JitterArgs, scratch: &Path) -> anyhow::Result<PathBuf> {
    if !a.spin && a.pin.is_none() {
        return Ok(a.config.clone());
    }
    let text = std::fs::read_to_string(&a.config)
        .with_context(|| format!("cannot read {}", a.config.display()))?;
    let mut doc: toml_edit::DocumentMut =
        text.parse().with_context(|| format!("{}", a.config.display()))?;
    if a.spin {
        doc["hwserver"]["wait"] = toml_edit::value("spin");
        doc["hwserver"]["response_spin_us"] = toml_edit::value(i64::from(a.period_us));
    }
    if let Some(pin) = a.pin {
        doc["timer"]["servo_cpu"] = toml_edit::value(0);
        doc["timer"]["hwserver_cpu"] = toml_edit::value(pin.hwserver_cpu());
    }
    let path = scratch.join("qmarc.toml");
    std::fs::write(&path, doc.to_string())?;
    Ok(path)
}

/// One loop's figures in one segment (µs).
#[derive(Debug, Clone, Serialize)]
pub struct LoopFigures {
    /// Cycles run.
    pub cycles: u64,
    /// Periods the segment covered: its cycles (the servo's settle included) and the missed
    /// ones. A servo segment that a fault ended covers fewer than the bare loop's.
    pub periods: u64,
    /// Wake latency against the intended expiry.
    pub wake_us: Pct,
    /// |interval between wakes − period|.
    pub period_error_us: Pct,
    /// Periods that expired without a cycle.
    pub missed: u64,
    /// Of those, the ones lost in host stalls (a wake ≥ 1 ms late, which no cycle of ours
    /// causes: the bare loop meets them too, at other times).
    pub missed_in_stalls: u64,
    /// Wakes more than 40 µs off the period.
    pub outside_40us: u64,
    /// Tick → DAC write acknowledged (the servo pipeline only).
    pub output_us: Option<Pct>,
    /// A fault that ended the servo segment, if any.
    pub fault: Option<String>,
}

impl LoopFigures {
    /// Missed periods outside host stalls.
    fn outside_stalls(&self) -> u64 {
        self.missed.saturating_sub(self.missed_in_stalls)
    }
}

/// One round.
#[derive(Debug, Clone, Serialize)]
pub struct Round {
    /// 1-based.
    pub round: u32,
    /// Which segment ran first: `bare` or `servo`.
    pub first: &'static str,
    /// When the round's first segment started, s after the rounds began.
    pub started_s: f64,
    /// The bare loop.
    pub bare: LoopFigures,
    /// The bare loop busy `--bare-work-us` after each wake (run between the other two).
    pub worked: Option<LoopFigures>,
    /// The servo pipeline.
    pub servo: LoopFigures,
    /// servo wake p99 ÷ bare wake p99.
    pub p99_ratio: f64,
    /// servo wake p99 − bare wake p99, µs.
    pub p99_diff_us: f64,
}

/// The rounds of one timer and what they say.
#[derive(Debug, Clone, Serialize)]
pub struct TimerResult {
    /// `timerfd`, `nanosleep`, `timerfd-periodic`.
    pub timer: String,
    /// Every round.
    pub rounds: Vec<Round>,
    /// Median over rounds of the p99 ratio.
    pub p99_ratio_median: f64,
    /// Smallest round ratio.
    pub p99_ratio_min: f64,
    /// Largest round ratio.
    pub p99_ratio_max: f64,
    /// Median over rounds of servo p99 − bare p99, µs.
    pub p99_diff_us_median: f64,
    /// The host was too noisy for the ratio to mean anything.
    pub noisy_host: bool,
    /// Why (empty when quiet).
    pub noisy_reasons: Vec<String>,
    /// Periods the servo missed in all rounds, and the bare loop.
    pub missed_servo: u64,
    /// Periods the bare loop missed in all rounds.
    pub missed_bare: u64,
    /// Periods the servo missed outside host stalls (a wake ≥ 1 ms late), in all rounds.
    pub missed_servo_outside_stalls: u64,
    /// And the bare loop.
    pub missed_bare_outside_stalls: u64,
    /// Periods the servo segments covered, all rounds.
    pub periods_servo: u64,
    /// And the bare loop's.
    pub periods_bare: u64,
    /// With `--bare-work-us`: the busy bare loop's missed periods, all rounds.
    pub missed_worked: Option<u64>,
    /// And outside host stalls.
    pub missed_worked_outside_stalls: Option<u64>,
    /// And the periods it covered.
    pub periods_worked: Option<u64>,
}

impl TimerResult {
    /// The missed periods of this timer's rounds.
    pub fn missed(&self) -> Missed {
        Missed {
            servo: self.missed_servo,
            bare: self.missed_bare,
            servo_outside_stalls: self.missed_servo_outside_stalls,
            bare_outside_stalls: self.missed_bare_outside_stalls,
            periods_servo: self.periods_servo,
            periods_bare: self.periods_bare,
        }
    }

    /// The busy bare loop's missed periods per 100 000, (all, outside host stalls).
    pub fn worked_rates(&self) -> Option<(f64, f64)> {
        let of = self.periods_worked?;
        Some((per_100k(self.missed_worked?, of), per_100k(self.missed_worked_outside_stalls?, of)))
    }
}

/// Missed periods of the servo pipeline and the bare loop, over one timer's rounds or over
/// every timer of the run (`--timer both|all`: the same-run comparison over all segments).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Missed {
    /// The servo pipeline's missed periods.
    pub servo: u64,
    /// The bare loop's.
    pub bare: u64,
    /// The servo's outside host stalls (a wake ≥ 1 ms late).
    pub servo_outside_stalls: u64,
    /// The bare loop's outside host stalls.
    pub bare_outside_stalls: u64,
    /// Periods the servo segments covered.
    pub periods_servo: u64,
    /// Periods the bare loop's segments covered.
    pub periods_bare: u64,
}

impl Missed {
    /// One round's: its servo segment's and its bare loop's.
    fn of_round(r: &Round) -> Missed {
        Missed {
            servo: r.servo.missed,
            bare: r.bare.missed,
            servo_outside_stalls: r.servo.outside_stalls(),
            bare_outside_stalls: r.bare.outside_stalls(),
            periods_servo: r.servo.periods,
            periods_bare: r.bare.periods,
        }
    }

    /// The sum over every timer of the run, when it ran more than one.
    pub fn of_all(results: &[TimerResult]) -> Option<Missed> {
        (results.len() > 1).then(|| results.iter().map(TimerResult::missed).sum())
    }

    /// Per 100 000 periods (servo, bare): `outside_stalls` only, or all.
    pub fn rates(&self, outside_stalls: bool) -> (f64, f64) {
        let (s, b) = if outside_stalls {
            (self.servo_outside_stalls, self.bare_outside_stalls)
        } else {
            (self.servo, self.bare)
        };
        (per_100k(s, self.periods_servo), per_100k(b, self.periods_bare))
    }
}

/// Rounds' or timers' missed periods added up, field by field.
impl std::iter::Sum for Missed {
    fn sum<I: Iterator<Item = Missed>>(all: I) -> Missed {
        all.fold(Missed::default(), |t, m| Missed {
            servo: t.servo + m.servo,
            bare: t.bare + m.bare,
            servo_outside_stalls: t.servo_outside_stalls + m.servo_outside_stalls,
            bare_outside_stalls: t.bare_outside_stalls + m.bare_outside_stalls,
            periods_servo: t.periods_servo + m.periods_servo,
            periods_bare: t.periods_bare + m.periods_bare,
        })
    }
}

/// `n` of `of` periods, per 100 000.
fn per_100k(n: u64, of: u64) -> f64 {
    n as f64 * 1e5 / of.max(1) as f64
}

/// The JSON `--json` writes: the first timer's verdict at the top, every timer's in `timers`.
#[derive(Debug, Serialize)]
struct Report<'a> {
    period_us: u32,
    rounds: u32,
    segment_s: f64,
    spin: bool,
    pin: Option<Pin>,
    machine: crate::ipc::Machine,
    p99_ratio_median: f64,
    p99_ratio_min: f64,
    p99_ratio_max: f64,
    p99_diff_us_median: f64,
    noisy_host: bool,
    timers: &'a [TimerResult],
    /// With several timers: their missed periods together.
    missed_all_timers: Option<Missed>,
    cyclictest: Option<crate::ipc::Cyclictest>,
}

/// The timers `--timer` names (`None`: the settings').
fn timers(choice: Option<&str>, configured: TimerMethod) -> anyhow::Result<Vec<TimerMethod>> {
    Ok(match choice {
        None => vec![configured],
        Some("both") => vec![TimerMethod::Timerfd, TimerMethod::Nanosleep],
        Some("all") => {
            vec![TimerMethod::Timerfd, TimerMethod::Nanosleep, TimerMethod::TimerfdPeriodic]
        }
        Some(one) => vec![one.parse::<TimerMethod>().map_err(anyhow::Error::msg)?],
    })
}

/// The bare loop for `seconds` with `kind`, at the servo thread's real-time request, busy
/// for `work_ns` after each wake (0: none, cyclictest's loop).
fn bare(
    kind: TickerKind,
    period_ns: u64,
    seconds: f64,
    req: RtRequest,
    work_ns: u64,
) -> anyhow::Result<LoopFigures> {
    let n = ((seconds * 1e9) / period_ns as f64).max(1.0) as u64;
    let handle = qmarc_timer::rt::spawn("qmarc-bare", req, move |_rt| {
        let _dma = DmaLatencyGuard::request_zero();
        let mut ticker = kind.build(period_ns);
        let mut stats = TimingStats::new(period_ns);
        ticker.start()?;
        let mut cycles = 0;
        while cycles < n {
            let tick = ticker.wait()?;
            stats.record_tick(&tick);
            cycles += 1 + tick.missed;
            while monotonic_now_ns() < tick.woke_ns + work_ns {
                std::hint::spin_loop();
            }
        }
        Ok::<_, qmarc_timer::TickerError>((stats, cycles))
    })?;
    let (stats, cycles) =
        handle.join().map_err(|_| anyhow::anyhow!("the bare loop panicked"))??;
    Ok(LoopFigures {
        cycles,
        periods: cycles,
        wake_us: stats.wake_latency.percentiles().into(),
        period_error_us: stats.period_error.percentiles().into(),
        missed: stats.missed,
        missed_in_stalls: stats.missed_in_stalls,
        outside_40us: stats.outside_40us,
        output_us: None,
        fault: None,
    })
}

/// One servo segment: `qmarc-starter step` for `seconds` with `timer`, its figures from its
/// summary.json.
fn servo(
    a: &JitterArgs,
    (starter, config): (&Path, &Path),
    timer: TimerMethod,
    out: &Path,
) -> anyhow::Result<LoopFigures> {
    let status = Command::new(starter)
        .arg(format!("--config={}", config.display()))
        .arg(format!("--out={}", out.display()))
        .arg(format!("--period-us={}", a.period_us))
        .arg(format!("--timer={timer}"))
        .args(["--gather-every=100", "step", "--size=1000"])
        .arg(format!("--duration={}", a.segment_s))
        .stdout(std::process::Stdio::null())
        .status()
        .with_context(|| format!("cannot run {}", starter.display()))?;
    let s = Summary::read(out).map_err(anyhow::Error::msg).with_context(|| {
        format!("the servo segment ({status}) left no summary in {}", out.display())
    })?;
    let t = &s.timing;
    Ok(LoopFigures {
        cycles: s.cycles,
        periods: s.cycles + s.settle.as_ref().map_or(0, |x| x.cycles) + t.missed_periods,
        wake_us: t.wake_latency_us,
        period_error_us: t.period_error_us,
        missed: t.missed_periods,
        missed_in_stalls: t.missed_in_stalls,
        outside_40us: t.outside_40us,
        output_us: Some(t.output_latency_us),
        fault: s.fault.map(|f| format!("{}: {}", f.kind, f.message)),
    })
}

/// Every round of every timer: in each round, each timer's segments in turn, the timers'
/// order turning round by round, so that every timer meets the same hour of the host
/// (its stalls decide the missed periods' totals).
fn all_rounds(
    a: &JitterArgs,
    timers: &[TimerMethod],
    req: RtRequest,
    scratch: &Path,
) -> anyhow::Result<Vec<TimerResult>> {
    let starter = qmarc_program::process::bin_dir(a.bin_dir.as_deref())?.join("qmarc-starter");
    let config = segment_config(a, scratch)?;
    let starter = (starter.as_path(), config.as_path());
    let period_ns = u64::from(a.period_us) * 1_000;
    let first = qmarc_controller_process::run::ticker_kind(timers[0]);
    bare(first, period_ns, a.warmup_s, req, 0)?;
    let mut rounds: Vec<Vec<Round>> = vec![Vec::new(); timers.len()];
    let began = std::time::Instant::now();
    for r in 1..=a.rounds {
        for k in 0..timers.len() {
            let i = (k + r as usize - 1) % timers.len();
            let started_s = began.elapsed().as_secs_f64();
            rounds[i].push(round_of(a, (timers[i], r, started_s), req, starter, scratch)?);
        }
    }
    let results = timers.iter().zip(rounds);
    Ok(results.map(|(timer, rs)| verdict(timer.to_string(), rs, a.period_us)).collect())
}

/// Round `r` of `timer`, begun `started_s` after the rounds: the bare loop, the busy one (with
/// `--bare-work-us`) and the servo pipeline, the bare loop first in odd rounds.
fn round_of(
    a: &JitterArgs,
    (timer, r, started_s): (TimerMethod, u32, f64),
    req: RtRequest,
    starter: (&Path, &Path),
    scratch: &Path,
) -> anyhow::Result<Round> {
    let period_ns = u64::from(a.period_us) * 1_000;
    let kind = qmarc_controller_process::run::ticker_kind(timer);
    let bare_for =
        |work_us: u32| bare(kind, period_ns, a.segment_s, req, u64::from(work_us) * 1_000);
    let worked = || a.bare_work_us.map(bare_for).transpose();
    let out = scratch.join(format!("{timer}-{r}"));
    let bare_first = r % 2 == 1;
    let (b, w, s) = if bare_first {
        let (b, w) = (bare_for(0)?, worked()?);
        (b, w, servo(a, starter, timer, &out)?)
    } else {
        let (s, w) = (servo(a, starter, timer, &out)?, worked()?);
        (bare_for(0)?, w, s)
    };
    let ratio = if b.wake_us.p99 > 0.0 { s.wake_us.p99 / b.wake_us.p99 } else { f64::NAN };
    let diff = s.wake_us.p99 - b.wake_us.p99;
    eprintln!(
        "  {timer} round {r}/{}: bare p99 {:.0} µs, servo p99 {:.0} µs, ratio {ratio:.2}",
        a.rounds, b.wake_us.p99, s.wake_us.p99
    );
    Ok(Round {
        round: r,
        first: if bare_first { "bare" } else { "servo" },
        started_s,
        bare: b,
        worked: w,
        servo: s,
        p99_ratio: ratio,
        p99_diff_us: diff,
    })
}

/// The ratios over the rounds and the noisy-host flag: the bare loop's p99.9 varying by more
/// than 30 % across rounds, or a bare-loop stall longer than a period.
pub fn verdict(timer: String, rounds: Vec<Round>, period_us: u32) -> TimerResult {
    let ratios: Vec<f64> = rounds.iter().map(|r| r.p99_ratio).collect();
    let diffs: Vec<f64> = rounds.iter().map(|r| r.p99_diff_us).collect();
    let p999: Vec<f64> = rounds.iter().map(|r| r.bare.wake_us.p999).collect();
    let mut noisy = Vec::new();
    let spread = cv(&p999);
    if spread > 0.30 {
        noisy
            .push(format!("the bare loop's p99.9 varies by {:.0} % across rounds", spread * 100.0));
    }
    let stall = rounds.iter().map(|r| r.bare.wake_us.max).fold(0.0, f64::max);
    if stall > f64::from(period_us) {
        noisy.push(format!("the bare loop stalled {stall:.0} µs, longer than a period"));
    }
    let finite = || ratios.iter().copied().filter(|r| r.is_finite());
    let missed: Missed = rounds.iter().map(Missed::of_round).sum();
    TimerResult {
        timer,
        p99_ratio_median: median(&ratios),
        p99_ratio_min: finite().fold(f64::INFINITY, f64::min),
        p99_ratio_max: finite().fold(f64::NEG_INFINITY, f64::max),
        p99_diff_us_median: median(&diffs),
        noisy_host: !noisy.is_empty(),
        noisy_reasons: noisy,
        missed_servo: missed.servo,
        missed_bare: missed.bare,
        missed_servo_outside_stalls: missed.servo_outside_stalls,
        missed_bare_outside_stalls: missed.bare_outside_stalls,
        periods_servo: missed.periods_servo,
        periods_bare: missed.periods_bare,
        missed_worked: worked_sum(&rounds, |w| w.missed),
        missed_worked_outside_stalls: worked_sum(&rounds, LoopFigures::outside_stalls),
        periods_worked: worked_sum(&rounds, |w| w.periods),
        rounds,
    }
}

/// The sum of `f` over the rounds' busy bare loops, when they ran.
fn worked_sum(rounds: &[Round], f: impl Fn(&LoopFigures) -> u64) -> Option<u64> {
    rounds.iter().map(|r| r.worked.as_ref().map(&f)).sum()
}

/// Runs `jitter`.
pub fn run(a: &JitterArgs) -> anyhow::Result<()> {
    let bad_segment = a.segment_s.is_nan() || a.segment_s <= 0.0;
    if a.rounds == 0 || bad_segment || !(100..=100_000).contains(&a.period_us) {
        bail!("--rounds must be ≥ 1, --segment-s > 0 and --period-us 100‥100000");
    }
    if a.spin && a.pin == Some(Pin::Same) {
        bail!("--spin needs the hwserver on a CPU of its own: --pin (split), not --pin=same");
    }
    let settings = qmarc_config::Settings::load(&a.config, &crate::cycle::names())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let req = RtRequest {
        priority: (settings.timer.servo_priority > 0).then_some(settings.timer.servo_priority),
        lock_memory: settings.timer.lock_memory,
        prefault_stack_bytes: 128 * 1024,
        cpu: if a.pin.is_some() { Some(0) } else { settings.timer.servo_cpu },
    };
    // Checked before the scratch directory exists: a bad --timer must not leave it behind.
    let timers = timers(a.timer.as_deref(), settings.timer.method)?;
    // As the starter does for the servo segments: the benchmark's own threads keep off the
    // loops' CPU when one is left (`--pin=same`), so both segments see the same neighbours.
    if let Some(pin) = a.pin {
        qmarc_timer::cpus::keep_off(&[0, pin.hwserver_cpu() as usize])?;
    }
    let scratch = std::env::temp_dir().join(format!("qmarc-bench-jitter-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let cyclic_before = crate::ipc::cyclictest(a.period_us, a.segment_s, req.priority);
    let results = all_rounds(a, &timers, req, &scratch);
    if results.is_err() {
        let _ = std::fs::remove_dir_all(&scratch);
    }
    let results = results?;
    let cyclic = crate::ipc::cyclictest_pair(cyclic_before, a.period_us, a.segment_s, req.priority);
    let _ = std::fs::remove_dir_all(&scratch);
    print!("{}", table::render(a, &results, cyclic.as_ref()));
    if let Some(path) = &a.json {
        let first = &results[0];
        let report = Report {
            period_us: a.period_us,
            rounds: a.rounds,
            segment_s: a.segment_s,
            spin: a.spin,
            pin: a.pin,
            machine: crate::ipc::Machine::here(),
            p99_ratio_median: first.p99_ratio_median,
            p99_ratio_min: first.p99_ratio_min,
            p99_ratio_max: first.p99_ratio_max,
            p99_diff_us_median: first.p99_diff_us_median,
            noisy_host: first.noisy_host,
            timers: &results,
            missed_all_timers: Missed::of_all(&results),
            cyclictest: cyclic,
        };
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("  JSON: {}", path.display());
    }
    Ok(())
}
