//! `qmarc-bench cycle`: the computation of one servo cycle — the generator's sample and the
//! law's step — for every registered generator × law and 1–4 motors, in-process and without
//! I/O (the cycle's exchanges are `ipc`'s). The act follows the command, as on a robot that
//! tracks; the figure is the mean over many cycles and the slowest batch of 1 000.

use anyhow::Context;
use qmarc_config::{Names, Settings};
use qmarc_controller::law::ServoInput;
use qmarc_controller::traj::Sample;
use qmarc_plugins::registry::{GENERATORS, LAWS};
use qmarc_proto::MAX_MOTORS;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `cycle`.
#[derive(Debug, clap::Args)]
pub struct CycleArgs {
    /// Cycles per row.
    #[arg(long, default_value_t = 200_000)]
    pub cycles: u64,
    /// Settings file the generators and laws are built from.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
}

/// The names the registries accept (the starter's).
pub fn names() -> Names {
    qmarc_plugins::registry::names()
}

/// Writes knot files for `n` motors long enough for `cycles` samples at 400 µs: whole periods
/// of a slow raised cosine (1 Hz, 2000 counts: from rest to rest, well within the motion
/// limits) through knots 20 ms apart (spline) and the same as PVT knots.
fn knot_files(dir: &Path, n: usize, cycles: u64) -> anyhow::Result<(PathBuf, PathBuf)> {
    use std::fmt::Write;
    let knots = ((cycles as f64 * 0.0004 / 0.02).ceil() as usize + 10).div_ceil(50) * 50 + 1;
    let at = |k: usize| (1.0 - (k as f64 * 0.02 * std::f64::consts::TAU).cos()) * 1000.0;
    let (mut spline, mut pvt) = (format!("{knots}\n"), String::new());
    for k in 0..knots {
        let _ = write!(spline, "{:.2}", k as f64 * 0.02);
        for _ in 0..n {
            let _ = write!(spline, "\t{:.0}", at(k));
        }
        spline.push('\n');
        for (m, label) in ["X", "Y", "Z", "W"].iter().take(n).enumerate() {
            let v = (at(k + 1) - at(k)) / 0.02;
            let _ = write!(
                pvt,
                "{}{label}\t{:.0}\t{v:.1}\t20.0",
                if m == 0 { "" } else { "\t" },
                at(k)
            );
        }
        pvt.push('\n');
    }
    let (s, p) = (dir.join(format!("spline-{n}.txt")), dir.join(format!("pvt-{n}.txt")));
    std::fs::write(&s, spline)?;
    std::fs::write(&p, pvt)?;
    Ok((s, p))
}

/// Mean ns per cycle over `cycles`, and the slowest batch of 1 000 (ns per cycle); `None` when
/// the generator cannot start here (homing needs switches to find, a line or the pick cycle
/// the Delta's three motors).
fn time_one(
    settings: &Settings,
    generator: usize,
    law: usize,
    cycles: u64,
) -> anyhow::Result<Option<(f64, f64)>> {
    let n = settings.n_motors;
    let Ok(mut g) = (GENERATORS[generator].build)(settings) else { return Ok(None) };
    let mut law = (LAWS[law].build)(settings);
    // Where its path starts (the pick cycle's pick point), else at 0.
    let start = g.first_command().ok().flatten().unwrap_or([0.0; MAX_MOTORS]);
    if g.start(&start).is_err() {
        return Ok(None);
    }
    law.reset(&start, &start);
    let (mut cmd, mut act, mut dac) = ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS], [0; MAX_MOTORS]);
    let (mut worst, mut done) = (0.0f64, 0u64);
    let t0 = Instant::now();
    while done < cycles {
        let b0 = Instant::now();
        for i in 0..1_000u64 {
            let k = done + i;
            if !matches!(g.sample(k, &mut cmd), Sample::Ready) {
                return Ok(Some((t0.elapsed().as_nanos() as f64 / k.max(1) as f64, worst)));
            }
            law.step(&ServoInput { n: k, elapsed: 1, cmd: &cmd, act: &act }, &mut dac);
            black_box(&dac);
            act[..n].copy_from_slice(&cmd[..n]);
        }
        worst = worst.max(b0.elapsed().as_nanos() as f64 / 1_000.0);
        done += 1_000;
    }
    Ok(Some((t0.elapsed().as_nanos() as f64 / done as f64, worst)))
}

/// A slow move far enough to last many cycles: to 6000 counts on every motor, or along the
/// line to a point (three motors only; the line's settings need the Delta).
fn moving(s: &mut Settings, linear: bool) {
    let _ = s.set_move_to(&vec![6_000.0; s.n_motors]);
    let _ = s.set_move_speed(0.01);
    if linear && s.set_move_xyz([80.0, -40.0, -660.0]).is_ok() {
        let _ = s.set_move_linear();
    }
}

/// The online generator's recomputation when a new target arrives mid-motion, 3 motors at
/// the settings' limits: `targets` random targets, each from the state the profile is in
/// somewhere along the last one. Each recomputation is timed `REPEATS` times from the same
/// state and its fastest kept, so a preemption of this shared VM is not taken for the
/// computation's cost; ns per recomputation (mean, p99, worst), and the worst single timing.
fn retargets(base: &Settings, targets: usize) -> (f64, f64, f64, f64) {
    use qmarc_plugins::motion::MotionLimits;
    use qmarc_plugins::motion::{MotionState, Profile};
    const REPEATS: usize = 5;
    let limits = MotionLimits::of(base);
    let mut profile = Profile::new(3, [0.0; MAX_MOTORS]);
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut times, mut single) = (Vec::with_capacity(targets), 0.0f64);
    let mut from = MotionState::default();
    for _ in 0..targets {
        let mut target = [0.0; MAX_MOTORS];
        for t in target.iter_mut().take(3) {
            *t = -9_000.0 + next() * 19_000.0;
        }
        let mut fastest = f64::INFINITY;
        for _ in 0..REPEATS {
            let t0 = Instant::now();
            let planned = profile.plan(black_box(&from), black_box(&target), &limits);
            let ns = t0.elapsed().as_nanos() as f64;
            black_box(planned.is_ok());
            fastest = fastest.min(ns);
            single = single.max(ns);
        }
        times.push(fastest);
        from = profile.state_at(next() * profile.duration());
    }
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    (mean, times[times.len() * 99 / 100], *times.last().unwrap_or(&0.0), single)
}

/// Runs `cycle`.
pub fn run(a: &CycleArgs) -> anyhow::Result<()> {
    let base = Settings::load(&a.config, &names()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let dir = std::env::temp_dir().join(format!("qmarc-bench-cycle-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!(
        "qmarc-bench cycle: trajectory sample + law step, ns per cycle (mean; slowest batch of 1000)"
    );
    println!(
        "  {:<8} {:<8} {:>12} {:>12} {:>12} {:>12}",
        "law", "method", "1 motor", "2 motors", "3 motors", "4 motors"
    );
    let mut skipped = false;
    for (l, law) in LAWS.iter().enumerate() {
        for (g, generator) in GENERATORS.iter().enumerate() {
            let mut cells = Vec::new();
            for n in 1..=MAX_MOTORS {
                let mut s = base.clone();
                s.set_n_motors(n).map_err(|e| anyhow::anyhow!("{e}"))?;
                s.step.duration_s = 3_600.0;
                let (spline, pvt) = knot_files(&dir, n, a.cycles)?;
                s.set_knots(if generator.name == "pvt" { &pvt } else { &spline });
                moving(&mut s, generator.name == "linear");
                let cell = time_one(&s, g, l, a.cycles)
                    .with_context(|| format!("{} × {}, {n} motors", law.name, generator.name))?;
                skipped |= cell.is_none();
                cells.push(
                    cell.map_or("—".to_string(), |(mean, worst)| {
                        format!("{mean:.0} ({worst:.0})")
                    }),
                );
            }
            println!(
                "  {:<8} {:<8} {:>12} {:>12} {:>12} {:>12}",
                law.name, generator.name, cells[0], cells[1], cells[2], cells[3]
            );
        }
    }
    if skipped {
        println!("  (— : the generator could not start here)");
    }
    let (mean, p99, worst, single) = retargets(&base, 10_000);
    println!(
        "  online move, a new target mid-motion (3 motors, 10 000 random targets from moving \
         states, each the fastest of 5): recomputation mean {:.1} µs, p99 {:.1} µs, worst \
         {:.1} µs (worst single timing, preemptions included: {:.1} µs)",
        mean / 1e3,
        p99 / 1e3,
        worst / 1e3,
        single / 1e3
    );
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
