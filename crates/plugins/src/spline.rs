//! The offline trajectory (thesis 3.12.1): a natural cubic spline through non-uniformly spaced
//! knots, solved in O(N) and sampled into the whole command queue before the move.
//!
//! [`NaturalSpline`] is one channel (Press et al., *Numerical Recipes*, `spline`/`splint`):
//! the second derivatives y″ solve the tridiagonal system of eq. 3-7 with y″ = 0 at both ends;
//! between knots j and j+1 the curve is eq. 3-3, y = A·y_j + B·y_{j+1} + C·y″_j + D·y″_{j+1}.
//! [`CubicSpline`] is the generator: one spline per motor, sampled at t₀ + n·T.

use crate::source::{CommandQueue, KnotSource, QUEUE_BUDGET_BYTES, TrajBuildError, knots_failed};
use qmarc_config::Settings;
use qmarc_controller::traj::{TrajStartError, TrajectoryGenerator, check_start};
use qmarc_knots::dynamics::{Excess, check_segment};
use qmarc_knots::{
    KnotFileError, KnotRules, MAX_KNOT_FILE_BYTES, OfflineKnots, parse_offline, read_knot_file,
    text_of,
};
use qmarc_proto::MAX_MOTORS;
use std::io::Read;

/// A natural cubic spline through (tᵢ, yᵢ). Coefficients are solved once in
/// [`NaturalSpline::new`]; evaluation caches the segment it found last, so a monotone sweep
/// costs O(1) per query.
#[derive(Debug, Clone, PartialEq)]
pub struct NaturalSpline {
    t: Vec<f64>,
    y: Vec<f64>,
    y2: Vec<f64>,
    cursor: usize,
}

/// The knots cannot carry a spline (defined with the other reasons a path cannot be built).
pub use crate::source::SplineError;

impl NaturalSpline {
    /// Solves the natural spline through `(t[i], y[i])` in O(N): the tridiagonal system of
    /// thesis eq. 3-7 by forward elimination and back substitution, y″₀ = y″ₙ₋₁ = 0.
    pub fn new(t: Vec<f64>, y: Vec<f64>) -> Result<NaturalSpline, SplineError> {
        let n = t.len();
        if n != y.len() {
            return Err(SplineError::Mismatch { times: n, values: y.len() });
        }
        if n < 2 {
            return Err(SplineError::TooFew(n));
        }
        if let Some(i) = (0..n).find(|&i| !t[i].is_finite() || (i > 0 && t[i] <= t[i - 1])) {
            return Err(SplineError::NotIncreasing(i));
        }
        let mut y2 = vec![0.0; n];
        let mut u = vec![0.0; n];
        for i in 1..n - 1 {
            let sig = (t[i] - t[i - 1]) / (t[i + 1] - t[i - 1]);
            let p = sig * y2[i - 1] + 2.0;
            y2[i] = (sig - 1.0) / p;
            let slope =
                (y[i + 1] - y[i]) / (t[i + 1] - t[i]) - (y[i] - y[i - 1]) / (t[i] - t[i - 1]);
            u[i] = (6.0 * slope / (t[i + 1] - t[i - 1]) - sig * u[i - 1]) / p;
        }
        y2[n - 1] = 0.0;
        for k in (0..n - 1).rev() {
            y2[k] = y2[k] * y2[k + 1] + u[k];
        }
        Ok(NaturalSpline { t, y, y2, cursor: 0 })
    }

    /// The knot times.
    pub fn times(&self) -> &[f64] {
        &self.t
    }

    /// The second derivatives at the knots.
    pub fn second_derivatives(&self) -> &[f64] {
        &self.y2
    }

    /// The segment j with t_j ≤ t ≤ t_{j+1} (clamped to the ends): the cached one or its
    /// successor if t is there, otherwise by bisection.
    fn segment(&mut self, t: f64) -> usize {
        let last = self.t.len() - 2;
        let c = self.cursor.min(last);
        let j = if self.t[c] <= t && t <= self.t[c + 1] {
            c
        } else if c < last && self.t[c + 1] <= t && t <= self.t[c + 2] {
            c + 1
        } else {
            // Bisection on [lo, hi): the last knot ≤ t.
            let (mut lo, mut hi) = (0, self.t.len() - 1);
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if self.t[mid] > t { hi = mid } else { lo = mid }
            }
            lo.min(last)
        };
        self.cursor = j;
        j
    }

    /// A, B and the segment length h of eq. 3-4 at `t` in segment `j`.
    fn weights(&self, j: usize, t: f64) -> (f64, f64, f64) {
        let h = self.t[j + 1] - self.t[j];
        ((self.t[j + 1] - t) / h, (t - self.t[j]) / h, h)
    }

    /// Position at `t` (eq. 3-3 to 3-6). Outside the knots, the end segments' cubics.
    pub fn position(&mut self, t: f64) -> f64 {
        let j = self.segment(t);
        self.position_in(j, t)
    }

    /// First derivative at `t`.
    pub fn velocity(&mut self, t: f64) -> f64 {
        let j = self.segment(t);
        self.velocity_in(j, t)
    }

    /// Second derivative at `t`.
    pub fn acceleration(&mut self, t: f64) -> f64 {
        let j = self.segment(t);
        self.acceleration_in(j, t)
    }

    fn position_in(&self, j: usize, t: f64) -> f64 {
        let (a, b, h) = self.weights(j, t);
        a * self.y[j]
            + b * self.y[j + 1]
            + ((a * a * a - a) * self.y2[j] + (b * b * b - b) * self.y2[j + 1]) * h * h / 6.0
    }

    fn velocity_in(&self, j: usize, t: f64) -> f64 {
        let (a, b, h) = self.weights(j, t);
        (self.y[j + 1] - self.y[j]) / h - (3.0 * a * a - 1.0) / 6.0 * h * self.y2[j]
            + (3.0 * b * b - 1.0) / 6.0 * h * self.y2[j + 1]
    }

    fn acceleration_in(&self, j: usize, t: f64) -> f64 {
        let (a, b, _) = self.weights(j, t);
        a * self.y2[j] + b * self.y2[j + 1]
    }
}

/// Samples of a path from `t0` to `t_end` at `period_s`: (duration / period) + 1, the thesis'
/// queue size (3.8.1.1.4), counting the sample at t₀.
pub fn samples_between(t0: f64, t_end: f64, period_s: f64) -> u64 {
    ((t_end - t0) / period_s + 1e-9).floor() as u64 + 1
}

/// A stream's whole offline knot file, at most [`MAX_KNOT_FILE_BYTES`], parsed.
fn read_offline_stream(
    source: &KnotSource,
    rules: &KnotRules,
) -> Result<OfflineKnots, KnotFileError> {
    let (name, mut reader) = source.open()?;
    let mut raw = Vec::new();
    reader
        .by_ref()
        .take(MAX_KNOT_FILE_BYTES + 1)
        .read_to_end(&mut raw)
        .map_err(|e| KnotFileError::Read { file: name.clone(), reason: e.to_string() })?;
    if raw.len() as u64 > MAX_KNOT_FILE_BYTES {
        return Err(KnotFileError::TooLarge { file: name, limit: MAX_KNOT_FILE_BYTES });
    }
    parse_offline(&name, &text_of(&name, raw)?, rules)
}

/// The offline cubic-spline generator: the whole command queue is computed before the move.
#[derive(Debug)]
#[doc(alias = "CubSplineTrajGen")]
pub struct CubicSpline {
    source: KnotSource,
    n_motors: usize,
    rules: KnotRules,
    /// A stream's whole file must arrive within this.
    stream_wait: std::time::Duration,
    period_s: f64,
    start_tolerance: f64,
    /// The samples, and each motor's velocity at the last knot, counts/s.
    queue: CommandQueue,
}

impl CubicSpline {
    /// The generator for `knots` (already parsed): solves one spline per motor and samples
    /// every servo period from the first knot to the last into the command queue.
    pub fn from_knots(
        knots: &OfflineKnots,
        period_s: f64,
        start_tolerance: f64,
    ) -> Result<CubicSpline, TrajBuildError> {
        let mut g = CubicSpline {
            source: KnotSource::Stdin,
            n_motors: knots.n_motors,
            rules: KnotRules::new(knots.n_motors),
            stream_wait: std::time::Duration::from_secs(10),
            period_s,
            start_tolerance,
            queue: CommandQueue::default(),
        };
        g.compute(knots)?;
        Ok(g)
    }

    /// The generator of the settings: `trajectory.knots` for `general.n_motors`. A regular
    /// file is read, checked and sampled now; a stream (`-`, a FIFO) when the move starts.
    pub fn from_settings(s: &Settings) -> Result<CubicSpline, TrajBuildError> {
        let source = KnotSource::from_settings(s)?;
        let mut g = CubicSpline {
            source: source.clone(),
            n_motors: s.n_motors,
            rules: KnotRules::from_settings(s),
            stream_wait: std::time::Duration::from_secs_f64(s.trajectory.stream_wait_s),
            period_s: s.period_s(),
            start_tolerance: s.trajectory.start_tolerance_counts,
            queue: CommandQueue::default(),
        };
        if let KnotSource::File(path) = &source {
            let text = read_knot_file(path)?;
            g.compute(&parse_offline(&path.display().to_string(), &text, &g.rules)?)?;
        }
        Ok(g)
    }

    fn compute(&mut self, knots: &OfflineKnots) -> Result<(), TrajBuildError> {
        let (t0, t_end) = (knots.times[0], knots.times[knots.times.len() - 1]);
        let samples = samples_between(t0, t_end, self.period_s);
        let bytes = samples.saturating_mul(std::mem::size_of::<[f64; MAX_MOTORS]>() as u64);
        if bytes > QUEUE_BUDGET_BYTES {
            return Err(TrajBuildError::Budget {
                seconds: t_end - t0,
                samples,
                bytes,
                budget: QUEUE_BUDGET_BYTES,
            });
        }
        let mut splines = Vec::with_capacity(self.n_motors);
        for m in 0..self.n_motors {
            let y = knots.positions.iter().map(|p| p[m]).collect();
            splines
                .push(NaturalSpline::new(knots.times.clone(), y).map_err(TrajBuildError::Spline)?);
        }
        self.check_dynamics(knots, &splines)?;
        let mut queue = Vec::with_capacity(samples as usize);
        for n in 0..samples {
            let t = t0 + n as f64 * self.period_s;
            let mut cmd = [0.0; MAX_MOTORS];
            for (c, s) in cmd.iter_mut().zip(&mut splines) {
                *c = s.position(t);
            }
            queue.push(cmd);
        }
        let mut end_velocity = [0.0; MAX_MOTORS];
        for (v, s) in end_velocity.iter_mut().zip(&mut splines) {
            *v = s.velocity(t_end);
        }
        self.queue = CommandQueue::ending_with(queue, end_velocity);
        Ok(())
    }

    /// Refuses a path that asks a motor more than its limits (`rules`): every segment of
    /// every motor's spline, naming the line of the knot the segment leads to.
    fn check_dynamics(
        &self,
        knots: &OfflineKnots,
        splines: &[NaturalSpline],
    ) -> Result<(), TrajBuildError> {
        let rules = &self.rules;
        let fail = |i: usize, e: Excess| {
            TrajBuildError::Knots(KnotFileError::Invalid {
                file: knots.file.clone(),
                line: knots.lines.get(i).copied().unwrap_or(0),
                column: 1,
                message: e.describe(),
            })
        };
        for (m, s) in splines.iter().enumerate() {
            let (t, y2) = (s.times(), s.second_derivatives());
            for j in 0..t.len() - 1 {
                let seg = (s.velocity_in(j, t[j]), y2[j], y2[j + 1], t[j + 1] - t[j]);
                check_segment(rules, m, seg).map_err(|e| fail(j + 1, e))?;
            }
        }
        Ok(())
    }

    /// Reads and parses a stream's whole file in a helper thread (opening a FIFO blocks until
    /// a writer comes), waiting at most `stream_wait` and ending at once on a stop signal.
    fn read_stream(&mut self) -> Result<(), TrajStartError> {
        let (source, rules) = (self.source.clone(), self.rules);
        let (tx, rx) = std::sync::mpsc::channel();
        qmarc_timer::rt::spawn_normal("qmarc-knots", move || {
            let _ = tx.send(read_offline_stream(&source, &rules));
        })
        .map_err(|e| {
            knots_failed(KnotFileError::Read {
                file: self.source.name(),
                reason: format!("reader thread: {e}"),
            })
        })?;
        let started = std::time::Instant::now();
        let knots = loop {
            match rx.recv_timeout(std::time::Duration::from_millis(10)) {
                Ok(result) => break result.map_err(knots_failed)?,
                Err(_) if qmarc_timer::stop::requested() => {
                    return Err(TrajStartError::Interrupted { stream: self.source.name() });
                }
                Err(_) if started.elapsed() < self.stream_wait => {}
                Err(_) => {
                    return Err(TrajStartError::NoKnots {
                        stream: self.source.name(),
                        got: 0,
                        needed: 2,
                        waited_s: self.stream_wait.as_secs_f64(),
                    });
                }
            }
        };
        self.compute(&knots).map_err(TrajStartError::from)
    }

    /// The command queue.
    pub fn queue(&self) -> &[[f64; MAX_MOTORS]] {
        self.queue.commands()
    }
}

impl TrajectoryGenerator for CubicSpline {
    fn name(&self) -> &'static str {
        "spline"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        if self.queue.is_empty() {
            self.read_stream()?;
        }
        check_start(start, &self.queue.commands()[0], self.n_motors, self.start_tolerance)
    }

    /// The first knot (a stream's whole file is read for it).
    fn first_command(&mut self) -> Result<Option<[f64; MAX_MOTORS]>, TrajStartError> {
        if self.queue.is_empty() {
            self.read_stream()?;
        }
        Ok(Some(self.queue.commands()[0]))
    }

    crate::source::follows_queue!(queue, sample);
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use qmarc_controller::traj::Sample;

    fn spline(t: &[f64], y: &[f64]) -> NaturalSpline {
        NaturalSpline::new(t.to_vec(), y.to_vec()).unwrap()
    }

    #[test]
    fn two_knots_give_a_straight_line() {
        let mut s = spline(&[0.0, 2.0], &[10.0, 30.0]);
        assert_eq!(s.second_derivatives(), &[0.0, 0.0]);
        assert_eq!(s.position(0.5), 15.0);
        assert_eq!(s.velocity(1.7), 10.0);
        assert_eq!(s.acceleration(1.0), 0.0);
    }

    #[test]
    fn three_symmetric_knots_match_the_hand_solution() {
        // t = 0, 1, 2; y = 0, 1, 0. Eq. 3-7 at j = 1: (1/6)·0 + (2/3)·y″₁ + (1/6)·0 = −1 − 1,
        // so y″₁ = −3; at t = 0.5: A = B = 0.5, C = D = (0.125 − 0.5)/6 = −1/16:
        // y = 0.5 + (−1/16)(−3) = 0.6875.
        let mut s = spline(&[0.0, 1.0, 2.0], &[0.0, 1.0, 0.0]);
        assert_eq!(s.second_derivatives(), &[0.0, -3.0, 0.0]);
        assert_eq!(s.position(0.5), 0.6875);
        assert_eq!(s.position(1.5), 0.6875);
        assert_eq!(s.velocity(1.0), 0.0);
    }

    #[test]
    fn bad_knots_are_refused() {
        assert_eq!(NaturalSpline::new(vec![0.0], vec![1.0]), Err(SplineError::TooFew(1)));
        assert_eq!(
            NaturalSpline::new(vec![0.0, 0.0], vec![1.0, 2.0]),
            Err(SplineError::NotIncreasing(1))
        );
        assert!(matches!(
            NaturalSpline::new(vec![0.0, 1.0], vec![1.0]),
            Err(SplineError::Mismatch { .. })
        ));
    }

    #[test]
    fn queue_holds_duration_over_period_plus_one_samples_from_the_first_knot() {
        let knots = OfflineKnots {
            times: vec![1.0, 1.25, 1.5],
            positions: vec![[0.0; 4], [2000.0, -2000.0, 0.0, 0.0], [3000.0, -4500.0, 0.0, 0.0]],
            n_motors: 2,
            ..OfflineKnots::default()
        };
        let mut g = CubicSpline::from_knots(&knots, 0.0004, 10.0).unwrap();
        assert_eq!(g.samples(), Some(1251));
        let mut cmd = [9.0; 4];
        assert_eq!(g.sample(0, &mut cmd), Sample::Ready);
        assert_eq!(cmd, [0.0; 4]);
        g.sample(625, &mut cmd);
        assert!((cmd[0] - 2000.0).abs() < 1e-9 && (cmd[1] + 2000.0).abs() < 1e-9, "{cmd:?}");
        g.sample(1250, &mut cmd);
        assert!((cmd[0] - 3000.0).abs() < 1e-9, "{cmd:?}");
        assert_eq!(g.sample(1251, &mut cmd), Sample::Done);
        // The path starts where the robot is, within the tolerance.
        assert!(g.start(&[5.0, -5.0, 0.0, 0.0]).is_ok());
        let e = g.start(&[0.0, 50.0, 0.0, 0.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "motor 2 is at 50 counts but the path starts at 0 counts, more than the 10-count start \
             tolerance away: move it there first (`run --approach` does)"
        );
    }

    /// Issue 27, item 2: a spline that asks a motor more than its limits is refused before
    /// the move, naming the file, the line of the knot the offending segment leads to, and
    /// the motor; the same path within its limits, or without limits, runs.
    #[test]
    fn a_spline_beyond_the_motion_limits_is_refused_naming_the_knot() {
        let text = "4\n0.0 0 0\n0.5 0 0\n0.75 5000 0\n1.0 5000 0\n";
        let mut rules = KnotRules::new(2);
        rules.max_velocity = [80_000.0; MAX_MOTORS];
        rules.max_acceleration = [5e6; MAX_MOTORS];
        let build = |text: &str, rules: KnotRules| {
            let knots = parse_offline("k.txt", text, &rules).unwrap();
            let mut g = CubicSpline::from_knots(&knots, 400e-6, 10.0).unwrap();
            g.rules = rules;
            g.compute(&knots).map(|()| g)
        };
        // A natural spline through a step of 5000 counts in 0.25 s: too fast for a motor
        // limited to 20 000 counts/s, and too hard an acceleration for 10⁵ counts/s².
        rules.max_velocity[0] = 20_000.0;
        assert_eq!(
            build(text, rules).unwrap_err().to_string(),
            "k.txt:4:1: motor 1: the path moves at 22826 counts/s on its way to this knot, \
             faster than motor 1's max_velocity_counts_per_s = 20000"
        );
        rules.max_velocity[0] = 80_000.0;
        rules.max_acceleration[0] = 1e5;
        assert_eq!(
            build(text, rules).unwrap_err().to_string(),
            "k.txt:3:1: motor 1: the path accelerates at 104348 counts/s² on its way to this \
             knot, more than motor 1's max_acceleration_counts_per_s2 = 100000"
        );
        rules.max_acceleration[0] = 5e6;
        assert!(build(text, rules).is_ok(), "within the shipped robot's limits");
        assert!(build(text, KnotRules::new(2)).is_ok(), "no limits, nothing checked");
    }

    /// Strictly increasing times with gaps of 1 ms‥1 s, values within ±10⁵ counts.
    fn knot_set() -> impl Strategy<Value = (Vec<f64>, Vec<f64>)> {
        (2usize..40).prop_flat_map(|n| {
            (
                proptest::collection::vec(0.001f64..1.0, n),
                proptest::collection::vec(-1e5f64..1e5, n),
                -10.0f64..10.0,
            )
                .prop_map(|(gaps, y, t0)| {
                    let mut t = Vec::with_capacity(gaps.len());
                    let mut acc = t0;
                    for g in gaps {
                        t.push(acc);
                        acc += g;
                    }
                    (t, y)
                })
        })
    }

    /// The second derivatives by a dense solve of the same equations (nalgebra LU): an
    /// evaluation that shares no code with the O(N) elimination.
    fn dense_y2(t: &[f64], y: &[f64]) -> Vec<f64> {
        let n = t.len();
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut r = nalgebra::DVector::<f64>::zeros(n);
        a[(0, 0)] = 1.0;
        a[(n - 1, n - 1)] = 1.0;
        for j in 1..n - 1 {
            a[(j, j - 1)] = (t[j] - t[j - 1]) / 6.0;
            a[(j, j)] = (t[j + 1] - t[j - 1]) / 3.0;
            a[(j, j + 1)] = (t[j + 1] - t[j]) / 6.0;
            r[j] = (y[j + 1] - y[j]) / (t[j + 1] - t[j]) - (y[j] - y[j - 1]) / (t[j] - t[j - 1]);
        }
        a.lu()
            .solve(&r)
            .expect("the spline system is diagonally dominant")
            .iter()
            .copied()
            .collect()
    }

    proptest! {
        #[test]
        fn spline_passes_through_every_knot((t, y) in knot_set()) {
            let mut s = NaturalSpline::new(t.clone(), y.clone()).unwrap();
            for (ti, yi) in t.iter().zip(&y) {
                prop_assert!((s.position(*ti) - yi).abs() <= 1e-9 * (1.0 + yi.abs()) + 1e-6);
            }
        }

        #[test]
        fn spline_is_c2_at_interior_knots_and_natural_at_the_ends((t, y) in knot_set()) {
            let mut s = NaturalSpline::new(t.clone(), y.clone()).unwrap();
            let scale = 1.0 + y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let h_min = t.windows(2).map(|w| w[1] - w[0]).fold(f64::MAX, f64::min);
            let tol_v = 1e-7 * scale / h_min;
            let tol_a = 1e-7 * scale / (h_min * h_min);
            for (j, &tj) in t.iter().enumerate().take(t.len() - 1).skip(1) {
                // Evaluate knot j from segment j − 1 (left) and segment j (right) explicitly.
                let (vl, al) = (s.velocity_in(j - 1, tj), s.acceleration_in(j - 1, tj));
                let (vr, ar) = (s.velocity_in(j, tj), s.acceleration_in(j, tj));
                prop_assert!((vl - vr).abs() <= tol_v, "velocity jump {} at knot {j}", vl - vr);
                prop_assert!((al - ar).abs() <= tol_a, "acceleration jump {} at knot {j}", al - ar);
            }
            prop_assert_eq!(s.acceleration(t[0]), 0.0);
            prop_assert!(s.acceleration(t[t.len() - 1]).abs() <= tol_a);
        }

        #[test]
        fn spline_agrees_with_a_dense_solve((t, y) in knot_set()) {
            let s = NaturalSpline::new(t.clone(), y.clone()).unwrap();
            let dense = dense_y2(&t, &y);
            let h_min = t.windows(2).map(|w| w[1] - w[0]).fold(f64::MAX, f64::min);
            let scale = (1.0 + y.iter().fold(0.0f64, |m, v| m.max(v.abs()))) / (h_min * h_min);
            for (a, b) in s.second_derivatives().iter().zip(&dense) {
                prop_assert!((a - b).abs() <= 1e-8 * scale, "{a} vs {b}");
            }
        }

        #[test]
        fn cursor_and_bisection_find_the_same_segment((t, y) in knot_set(), probes in proptest::collection::vec(0.0f64..1.0, 1..50)) {
            let mut cached = NaturalSpline::new(t.clone(), y).unwrap();
            let span = t[t.len() - 1] - t[0];
            for p in probes {
                let x = t[0] + p * span;
                let mut fresh = cached.clone();
                fresh.cursor = 0;
                let (a, b) = (cached.position(x), fresh.position(x));
                prop_assert!((a - b).abs() <= 1e-9 * (1.0 + a.abs()), "{a} vs {b} at {x}");
            }
        }
    }
}
