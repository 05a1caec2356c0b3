//! `qmarc-bench conveyor`: conveyor tracking as its user measures it — real
//! `qmarc-starter conveyor` sessions (three processes and the camera), their figures read
//! back from their own `summary.json` and `parts.csv`:
//!
//! - the run of the issue: picks a minute, missed parts, the grip error (the effector against
//!   the part when the gripper is told to close, and while it closes), and what limits the
//!   rate — the pick cycle (grip to grip) against the time between parts. The grip error is
//!   given twice: over every grip, and over the grips with no missed period from
//!   [`CALM_BEFORE_S`] before the closing order to its end — a host stall of this VM (no
//!   PREEMPT_RT) holds the DAC for milliseconds while the belt moves on, which the same
//!   gains on a real-time kernel never see;
//! - how far the rate goes: the part rate raised until a part is missed;
//! - the latencies the session measured: a part's exposure to the part in the queue, and
//!   its handing to the loop to the tick of the intercept's first command;
//! - the same run at 1 m/s;
//! - the intercept's computation in the servo cycle: the picker's sample timed in-process,
//!   every cycle and the cycles that plan an intercept.

use qmarc_config::Settings;
use qmarc_controller::traj::TrajectoryGenerator;
use qmarc_session::conveyor::picker::Picker;
use qmarc_session::conveyor::{BeltFrame, Pick};
use std::path::PathBuf;
use std::process::{Command, Stdio};

/// Options of `conveyor`.
#[derive(Debug, clap::Args)]
pub struct ConveyorArgs {
    /// Settings file of the sessions.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Length of the main run, s.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// The belt's speed, mm/s.
    #[arg(long, default_value_t = 500.0)]
    pub belt_mm_s: f64,
    /// Parts a minute of the main run.
    #[arg(long, default_value_t = 120.0)]
    pub parts_per_min: f64,
    /// Length of each run of the rate sweep and of the 1 m/s run, s (0: none).
    #[arg(long, default_value_t = 20.0)]
    pub sweep_seconds: f64,
    /// The sweep's step, parts a minute.
    #[arg(long, default_value_t = 30.0)]
    pub sweep_step: f64,
    /// Directory holding qmarc-starter and its children (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
}

/// How long before the gripper's closing order a missed period still counts against a grip,
/// s: the intercept's last part, which the closing starts from.
pub const CALM_BEFORE_S: f64 = 0.1;

/// The grips of a session with no missed period near them (see [`CALM_BEFORE_S`]).
#[derive(Debug, Clone, Default)]
struct Calm {
    /// Grips counted, and those left out for a missed period.
    grips: usize,
    stalled: usize,
    /// Their grip error, mm: max and RMS; and the largest while the gripper closed.
    max: f64,
    rms: f64,
    closing_max: f64,
}

/// One session's figures, from its files.
#[derive(Debug, Clone)]
pub(crate) struct Run {
    calm: Calm,
    summary: qmarc_report::summary::ConveyorSummary,
    /// Mean s from a grip to the place, and from the place to the next grip.
    with_part_s: f64,
    back_s: f64,
}

/// A conveyor session of `seconds` at `belt` mm/s and `ppm` parts a minute.
pub(crate) fn session(
    a: &ConveyorArgs,
    seconds: f64,
    belt: f64,
    ppm: f64,
    name: &str,
) -> anyhow::Result<Run> {
    let starter = qmarc_program::process::bin_dir(a.bin_dir.as_deref())?.join("qmarc-starter");
    let pid = std::process::id();
    let out = std::env::temp_dir().join(format!("qmarc-bench-conveyor-{name}-{pid}"));
    let output = Command::new(&starter)
        .arg(format!("--config={}", a.config.display()))
        .arg(format!("--out={}", out.display()))
        .arg(format!("--iox-prefix=qmarc_benchconv{name}_{pid}_"))
        .args(["conveyor", &format!("--seconds={seconds}"), &format!("--belt-mm-s={belt}")])
        .arg(format!("--parts-per-min={ppm}"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()?;
    let summary = qmarc_report::Summary::read(&out).map_err(anyhow::Error::msg);
    let parts = std::fs::read_to_string(out.join("parts.csv"));
    let gather = std::fs::read_to_string(out.join("gather.csv"));
    let _ = std::fs::remove_dir_all(&out);
    anyhow::ensure!(
        output.status.success(),
        "qmarc-starter conveyor: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary = summary?;
    let period = summary.period_us as f64 * 1e-6;
    let section = summary.conveyor.ok_or_else(|| anyhow::anyhow!("no conveyor section"))?;
    let parts = parts?;
    let (with_part_s, back_s) = cycle_parts(&parts, period);
    let s = Settings::load(&a.config, &qmarc_config::Names::any())?;
    let frame =
        BeltFrame::of(&s).ok_or_else(|| anyhow::anyhow!("the settings describe no Delta"))?;
    let before = (CALM_BEFORE_S / period).round() as u64;
    let calm = calm_grips(&frame, &parts, &gather?, (before, u64::from(s.gather.every)));
    Ok(Run { calm, summary: section, with_part_s, back_s })
}

/// The grips of `parts` (parts.csv) whose rows in `gather` (gather.csv, a row every `every`
/// cycles) from `before` cycles ahead of the closing order until the gripper reads closed
/// skip no cycle.
fn calm_grips(frame: &BeltFrame, parts: &str, gather: &str, (before, every): (u64, u64)) -> Calm {
    let mut lines = gather.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let rows: Vec<Vec<f64>> =
        lines.map(|l| l.split(',').map(|v| v.parse().unwrap_or(f64::NAN)).collect()).collect();
    let (Some(cyc), Some(grip), Some(conv), Some(a1), Some(a2), Some(a3)) =
        (col("cycle"), col("grip"), col("conv"), col("act1"), col("act2"), col("act3"))
    else {
        return Calm::default();
    };
    let act = |r: &[f64]| [r[a1], r[a2], r[a3]];
    let (mut calm, mut sq) = (Calm::default(), 0.0);
    for l in parts.lines().skip(1) {
        let f: Vec<f64> = l.split(',').map(|v| v.parse().unwrap_or(f64::NAN)).collect();
        if !l.contains(",picked,") || f.len() < 9 {
            continue;
        }
        let (at, error) = (f[6], f[8]);
        let part = (f[3], f[4], f[2]);
        let from = rows.partition_point(|r| r[cyc] < at - before as f64);
        let start = rows.partition_point(|r| r[cyc] < at);
        let end = start + rows[start..].iter().take_while(|r| r[grip] != 2.0).count();
        let window = &rows[from..end.min(rows.len())];
        if window.windows(2).any(|w| w[1][cyc] - w[0][cyc] > every as f64) {
            calm.stalled += 1;
            continue;
        }
        calm.grips += 1;
        calm.max = calm.max.max(error);
        sq += error * error;
        for r in &rows[start..end.min(rows.len())] {
            let e = frame.effector_error_mm(act(r), r[conv], part).unwrap_or(f64::INFINITY);
            calm.closing_max = calm.closing_max.max(e);
        }
    }
    calm.rms = if calm.grips > 0 { (sq / calm.grips as f64).sqrt() } else { 0.0 };
    calm
}

/// From `parts.csv`: the mean time from a grip to its place, and from a place to the next
/// grip, s (cycles of `period` s).
fn cycle_parts(csv: &str, period: f64) -> (f64, f64) {
    let mut picks: Vec<(f64, f64)> = csv
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            if f.get(5) != Some(&"picked") {
                return None;
            }
            Some((f.get(6)?.parse().ok()?, f.get(7)?.parse().ok()?))
        })
        .collect();
    picks.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mean =
        |v: Vec<f64>| if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 };
    let with = mean(picks.iter().map(|(g, p)| (p - g) * period).collect());
    let back = mean(picks.windows(2).map(|w| (w[1].0 - w[0].1) * period).collect());
    (with, back)
}

pub(crate) fn say(label: &str, r: &Run, ppm: f64) {
    let c = &r.summary;
    println!(
        "  {label}: {:.1} picks/min of {ppm:.0} parts/min, {} picked, {} missed, {} pending; grip \
         error max {:.2} mm, RMS {:.2} mm, while closing max {:.2} mm",
        c.picks_per_min,
        c.picked,
        c.missed,
        c.pending,
        c.grip_error_mm.max,
        c.grip_error_mm.rms,
        c.closing_error_max_mm
    );
    if let Some(l) = &c.latency_ms {
        let (q, h) = (&l.exposure_to_queue, &l.queue_to_command);
        println!(
            "    latency: a part's first exposure → in the queue p50 {:.2} ms, p99 {:.2} ms ({} \
             parts; the camera's own latency included); handed to the loop → the tick of its \
             intercept's first command p50 {:.2} ms, p99 {:.2} ms ({} picks)",
            q.p50, q.p99, q.count, h.p50, h.p99, h.count
        );
    }
    let k = &r.calm;
    println!(
        "    the {} grips with no missed period from {:.0} ms before the closing to its end ({} \
         left out): grip error max {:.2} mm, RMS {:.2} mm, while closing max {:.2} mm",
        k.grips,
        CALM_BEFORE_S * 1e3,
        k.stalled,
        k.max,
        k.rms,
        k.closing_max
    );
}

/// Runs `conveyor`.
pub fn run(a: &ConveyorArgs) -> anyhow::Result<()> {
    let s = Settings::load(&a.config, &qmarc_config::Names::any())?;
    println!(
        "qmarc-bench conveyor: {} (window {:?} mm, place {:?} mm, gripper {} s)",
        a.config.display(),
        s.conveyor.window_mm,
        s.conveyor.place_mm,
        s.s626.gripper_close_s
    );
    let main = session(a, a.seconds, a.belt_mm_s, a.parts_per_min, "main")?;
    say(&format!("{} s at {} mm/s", a.seconds, a.belt_mm_s), &main, a.parts_per_min);
    let between = 60.0 / a.parts_per_min;
    println!(
        "  the pick cycle: {:.3} s with the part (grip → place) + {:.3} s back to the belt (place \
         → next grip, the wait for the part included), one part every {between:.3} s",
        main.with_part_s, main.back_s,
    );
    if a.sweep_seconds > 0.0 {
        let mut rate = a.parts_per_min;
        let mut best = None;
        loop {
            rate += a.sweep_step;
            let r = session(a, a.sweep_seconds, a.belt_mm_s, rate, "sweep")?;
            say(&format!("sweep {} s", a.sweep_seconds), &r, rate);
            if r.summary.missed > 0 || rate > 1_000.0 {
                break;
            }
            best = Some(rate);
        }
        match best {
            Some(b) => println!("  the highest rate with none missed: {b:.0} parts/min"),
            None => println!(
                "  the highest rate with none missed: {:.0} parts/min (the main run's)",
                a.parts_per_min
            ),
        }
        let fast = session(a, a.sweep_seconds, 1_000.0, a.parts_per_min, "fast")?;
        say(&format!("{} s at 1000 mm/s", a.sweep_seconds), &fast, a.parts_per_min);
    }
    intercept_timing(&s)
}

/// The picker's sample timed in-process on a belt at the settings' speed, parts handed over
/// whenever it waits: every cycle, and the cycles that plan an intercept.
fn intercept_timing(s: &Settings) -> anyhow::Result<()> {
    let status = std::sync::Arc::new(qmarc_controller::status::LoopStatus::default());
    let (mut p, _serve, mut h) =
        Picker::new(s, status).ok_or_else(|| anyhow::anyhow!("the settings describe no Delta"))?;
    let frame = BeltFrame::of(s).ok_or_else(|| anyhow::anyhow!("no robot"))?;
    p.start(&frame.counts_at_mm(s.conveyor.place_mm)?)?;
    let per_cycle = (s.conveyor.speed_mm_s * s.period_s() / s.conveyor.mm_per_count).round() as i64;
    let (mut all, mut planning) = (Vec::new(), Vec::new());
    let (mut belt, mut id, mut gripper) =
        (0i64, 0u32, qmarc_proto::Gripper(qmarc_proto::Gripper::OPEN));
    let mut since = 0u64;
    let mut told = None;
    for n in 0..200_000u64 {
        belt += per_cycle;
        let mut handed = false;
        if h.shared.ready.load(std::sync::atomic::Ordering::Acquire) && h.picks.slots() == 2 {
            id += 1;
            let across = 40.0 * f64::from(id % 5) - 80.0;
            let start = s.conveyor.window_mm[0];
            let pick = Pick { id, belt_mm: start + 10.0, across_mm: across, latched_counts: belt };
            handed = h.picks.push(pick).is_ok();
        }
        p.belt(belt);
        let mut cmd = [0.0; qmarc_proto::MAX_MOTORS];
        let t0 = std::time::Instant::now();
        let _ = p.sample(n, &mut cmd);
        let ns = t0.elapsed().as_nanos() as u64;
        all.push(ns);
        if handed {
            planning.push(ns);
        }
        let now = p.gripper(gripper);
        if now != told {
            (told, since) = (now, n);
        }
        let there = n >= since + (s.s626.gripper_close_s / s.period_s()) as u64;
        gripper = qmarc_proto::Gripper(match (now, there) {
            (Some(true), true) => qmarc_proto::Gripper::CLOSE | qmarc_proto::Gripper::CLOSED,
            (Some(true), false) => qmarc_proto::Gripper::CLOSE,
            (_, true) => qmarc_proto::Gripper::OPEN,
            _ => 0,
        });
        while h.events.pop().is_ok() {}
    }
    let all = crate::stats::percentiles_us(&mut all);
    let n_planned = planning.len();
    let over = planning.iter().filter(|&&ns| ns > 20_000).count();
    let plan = crate::stats::percentiles_us(&mut planning);
    println!(
        "  the picker in the servo cycle (in-process, {} cycles): p50 {:.1} µs, p99 {:.1} µs, max \
         {:.1} µs; the {n_planned} cycles that plan an intercept: p50 {:.1} µs, p99 {:.1} µs, max \
         {:.1} µs, {over} over 20 µs (a maximum on a VM includes its host's preemptions)",
        200_000, all.p50, all.p99, all.max, plan.p50, plan.p99, plan.max
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_cycle_is_split_at_the_grips_and_places() {
        let csv = "h\n1,0,0,0,0,picked,100,200,0.1\n2,0,0,0,0,missed,-1,-1,nan\n3,0,0,0,0,picked,500,650,0.2\n";
        let (with, back) = super::cycle_parts(csv, 0.001);
        assert!((with - 0.125).abs() < 1e-12 && (back - 0.3).abs() < 1e-12, "{with} {back}");
    }

    /// A grip near a skipped cycle is left out; the others give the grip and closing errors.
    #[test]
    fn grips_near_a_missed_period_are_left_out() {
        let s = qmarc_config::Settings::load(
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/qmarc.toml")),
            &qmarc_config::Names::any(),
        )
        .unwrap();
        let f = super::BeltFrame::of(&s).unwrap();
        // The effector on the part's grip point at belt 400 mm, across 0, the belt at 0.
        let q = f.counts_up(400.0, 0.0, 0.0).unwrap();
        let row = |c: u64, grip: u8, dx: f64| {
            format!("{c},0,0,{},0,0,{},0,0,{},0,{grip},0", q[0] + dx, q[1], q[2])
        };
        let mut g =
            String::from("cycle,time_s,cmd1,act1,dac1,cmd2,act2,dac2,cmd3,act3,dac3,grip,conv\n");
        for c in 0..40u64 {
            let grip = match c {
                10..=14 | 30..=34 => 1,
                15..=19 | 35..=39 => 2,
                _ => 0,
            };
            if c != 25 {
                g += &row(c, grip, if c == 12 { 20.0 } else { 0.0 });
                g += "\n";
            }
        }
        let parts = "h\n1,0,0,400,0,picked,10,20,0.1\n2,0,0,400,0,picked,30,40,0.3\n";
        let calm = super::calm_grips(&f, parts, &g, (8, 1));
        assert_eq!((calm.grips, calm.stalled), (1, 1), "{calm:?}");
        assert_eq!(calm.max, 0.1);
        // 20 counts on one arm: most of a millimetre.
        assert!(calm.closing_max > 0.5 && calm.closing_max < 5.0, "{calm:?}");
    }

    #[test]
    fn no_picks_give_no_cycle() {
        assert_eq!(super::cycle_parts("h\n", 0.001), (0.0, 0.0));
    }
}
