//! The online generator against an independent Ruckig: PyPI's `ruckig`, the C++ library's
//! own Python binding (`tests/reference/ruckig_reference.py`), on many random moves of the
//! shipped robot's magnitudes — from rest and from a moving state. The duration must be the
//! reference's time-optimal one (well within a servo period), and the profile the same.
//!
//! The reference runs in the Python environment `scripts/test` makes (`target/pyenv`, from
//! `tests/requirements.txt`), or the interpreter `QMARC_PYTHON` names.

use qmarc_plugins::motion::MotionLimits;
use qmarc_plugins::motion::{MotionState, Profile};
use qmarc_proto::MAX_MOTORS;
use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

const T: f64 = 400e-6;
const CASES: usize = 600;
const TIMES: [f64; 5] = [0.1, 0.3, 0.5, 0.7, 0.9];
/// Counts per arm radian of the shipped robot (4096 counts/rev × 12 / 2π): the reference
/// works in radians and seconds, the units Ruckig is made for (in raw counts its root
/// finding fails, as the Rust port's does, which is why ours plans normalised).
const COUNTS_PER_RAD: f64 = 4096.0 * 12.0 / std::f64::consts::TAU;

/// The interpreter with `ruckig` installed.
fn python() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = std::env::var_os("QMARC_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/pyenv/bin/python3"));
    let ok = Command::new(&python)
        .args(["-c", "import ruckig"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "{} cannot import ruckig: run the tests with scripts/test, which installs \
         tests/requirements.txt into target/pyenv (or set QMARC_PYTHON)",
        python.display()
    );
    python
}

/// A small deterministic generator (the cases are the same on every run).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn within(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

struct Case {
    from: MotionState,
    to: [f64; MAX_MOTORS],
    limits: MotionLimits,
}

fn case(rng: &mut Lcg, moving: bool) -> Case {
    let speed = rng.within(0.05, 1.0);
    let limits = MotionLimits {
        velocity: [80_000.0; MAX_MOTORS],
        acceleration: [5.0e6; MAX_MOTORS],
        jerk: [2.0e9; MAX_MOTORS],
    }
    .at_speed(speed);
    let mut from = MotionState::default();
    let mut to = [0.0; MAX_MOTORS];
    for (m, target) in to.iter_mut().enumerate().take(3) {
        from.p[m] = rng.within(-9000.0, 10_000.0);
        *target = rng.within(-9000.0, 10_000.0);
        if moving {
            from.v[m] = rng.within(-1.0, 1.0) * limits.velocity[m];
            from.a[m] = rng.within(-0.9, 0.9) * limits.acceleration[m];
        }
    }
    Case { from, to, limits }
}

fn line(c: &Case, duration: f64) -> String {
    let mut words = vec!["3".to_string()];
    let l = &c.limits;
    for set in [&c.from.p, &c.from.v, &c.from.a, &c.to, &l.velocity, &l.acceleration, &l.jerk] {
        words.extend(set[..3].iter().map(|x| format!("{:e}", x / COUNTS_PER_RAD)));
    }
    words.push(TIMES.len().to_string());
    words.extend(TIMES.iter().map(|f| format!("{:e}", f * duration)));
    words.join(" ")
}

#[test]
fn durations_and_profiles_are_those_of_the_reference_ruckig() {
    let mut rng = Lcg(0x9e37_79b9_7f4a_7c15);
    let mut ours = Vec::new();
    let mut input = String::new();
    for i in 0..CASES {
        let c = case(&mut rng, i % 3 != 0);
        let mut p = Profile::new(3, c.from.p);
        p.plan(&c.from, &c.to, &c.limits).unwrap_or_else(|e| panic!("case {i}: {e}"));
        let d = p.duration();
        let at: Vec<[f64; MAX_MOTORS]> = TIMES.iter().map(|f| p.state_at(f * d).p).collect();
        input.push_str(&line(&c, d));
        input.push('\n');
        ours.push((c, d, at));
    }
    let mut child = Command::new(python())
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/reference/ruckig_reference.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("the reference runs");
    // Written from a thread: the reference answers while it reads, and a pipe holds 64 KiB.
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap().expect("the reference reads every case");
    assert!(out.status.success(), "the reference failed");
    let text = String::from_utf8(out.stdout).unwrap();
    let answers: Vec<&str> = text.lines().collect();
    assert_eq!(answers.len(), CASES);
    let mut worst_s: f64 = 0.0;
    for (i, ((c, d, at), answer)) in ours.iter().zip(&answers).enumerate() {
        let nums: Vec<f64> = answer
            .split_whitespace()
            .map(|w| w.parse().unwrap_or_else(|_| panic!("case {i}: the reference says {answer}")))
            .collect();
        let want = nums[0];
        worst_s = worst_s.max((d - want).abs());
        assert!(
            (d - want).abs() <= 1e-6 * want.max(1e-3),
            "case {i}: {d} s, the reference {want} s (from {:?} to {:?})",
            c.from,
            c.to
        );
        let scale = (0..3)
            .map(|m| (c.to[m] - c.from.p[m]).abs() + c.from.v[m].abs() * want)
            .fold(1.0, f64::max);
        for (k, ours_at) in at.iter().enumerate() {
            for m in 0..3 {
                let theirs = nums[1 + k * 3 + m] * COUNTS_PER_RAD;
                assert!(
                    (ours_at[m] - theirs).abs() <= 1e-6 * scale,
                    "case {i}, motor {}, at {} of the move: {} counts, the reference {theirs}",
                    m + 1,
                    TIMES[k],
                    ours_at[m]
                );
            }
        }
    }
    assert!(worst_s < T, "worst duration difference {worst_s} s");
    eprintln!("{CASES} moves: the largest duration difference is {worst_s:e} s");
}
