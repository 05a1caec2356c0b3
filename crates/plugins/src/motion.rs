//! Motion from one kinematic state to another under per-motor limits: the limits
//! ([`MotionLimits`], from the settings in one place), the command's state ([`MotionState`]),
//! Ruckig's time-synchronised, time-optimal jerk-limited planner ([`Profile`], the `rsruckig`
//! port) and the closed-form double-S time ([`double_s_duration`]). The jerk-limited moves
//! from rest to rest (`moveto`) and the online moves (`online`) stand on it.

use qmarc_config::Settings;
use qmarc_proto::MAX_MOTORS;
use rsruckig::prelude::{
    ControlInterface, DataArrayOrVec, InputParameter, Ruckig, ThrowErrorHandler, Trajectory,
};

/// The limits a jerk-limited move keeps, per motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Velocity, counts/s.
    pub velocity: [f64; MAX_MOTORS],
    /// Acceleration, counts/s².
    pub acceleration: [f64; MAX_MOTORS],
    /// Jerk, counts/s³.
    pub jerk: [f64; MAX_MOTORS],
}

impl MotionLimits {
    /// Each motor's `[[motor]]` limits.
    pub fn of(s: &Settings) -> MotionLimits {
        let mut l = MotionLimits {
            velocity: [1.0; MAX_MOTORS],
            acceleration: [1.0; MAX_MOTORS],
            jerk: [1.0; MAX_MOTORS],
        };
        for (m, safety) in s.safety.iter().enumerate().take(MAX_MOTORS) {
            l.velocity[m] = safety.max_velocity_counts_per_s;
            l.acceleration[m] = safety.max_acceleration_counts_per_s2;
            l.jerk[m] = safety.max_jerk_counts_per_s3;
        }
        l
    }

    /// The limits of the same motions played `speed` times as fast (0 < speed ≤ 1): a time
    /// scaling, velocity × speed, acceleration × speed², jerk × speed³.
    pub fn at_speed(self, speed: f64) -> MotionLimits {
        MotionLimits {
            velocity: self.velocity.map(|v| v * speed),
            acceleration: self.acceleration.map(|a| a * speed * speed),
            jerk: self.jerk.map(|j| j * speed * speed * speed),
        }
    }
}
/// The shortest rest-to-rest move of `d` counts under `v`, `a`, `j`, s: the double-S profile
/// in closed form (Biagiotti & Melchiorri, "Trajectory Planning for Automatic Machines",
/// 3.4): the time to reach `v`, plus a cruise if the distance allows one, else the profile
/// that turns back before `v` (and before `a`, for short moves).
pub fn double_s_duration(d: f64, v: f64, a: f64, j: f64) -> f64 {
    let d = d.abs();
    if d == 0.0 {
        return 0.0;
    }
    let to_v = if v * j >= a * a { a / j + v / a } else { 2.0 * (v / j).sqrt() };
    if d >= v * to_v {
        return d / v + to_v;
    }
    let tj = a / j;
    let ta = (tj + (tj * tj + 4.0 * d / a).sqrt()) / 2.0;
    if ta >= 2.0 * tj { 2.0 * ta } else { 4.0 * (d / (2.0 * j)).cbrt() }
}
/// How far a profile's extremum may read beyond a soft limit from rounding alone, counts
/// (a millionth of a count: nothing a motor can do).
pub const BOUND_ROUNDING: f64 = 1e-6;

/// The command's kinematic state: per motor, counts, counts/s, counts/s².
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MotionState {
    /// Position, counts.
    pub p: [f64; MAX_MOTORS],
    /// Velocity, counts/s.
    pub v: [f64; MAX_MOTORS],
    /// Acceleration, counts/s².
    pub a: [f64; MAX_MOTORS],
}

impl MotionState {
    /// At rest at `p`.
    pub fn at_rest(p: [f64; MAX_MOTORS]) -> MotionState {
        MotionState { p, ..MotionState::default() }
    }
}

/// Ruckig found no profile: a limit that is not a positive finite number, a state that is
/// not finite, or a numerical failure of its root finding.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("no jerk-limited profile from the command's state to the target")]
pub struct NoProfile;

/// The planner: one time-synchronised profile at a time, planned without allocating.
///
/// Ruckig plans in units where the largest distance (or the way to stop) is 1 and the move
/// lasts about 1: in raw counts and seconds its root finding fails on about one random move
/// in five of the shipped robot (10⁴ counts, 10⁹ counts/s³); normalised, on none of the
/// reference tests' thousands.
pub struct Profile {
    n: usize,
    otg: Ruckig<MAX_MOTORS, ThrowErrorHandler>,
    input: InputParameter<MAX_MOTORS>,
    trajectory: Trajectory<MAX_MOTORS>,
    at: [DataArrayOrVec<f64, MAX_MOTORS>; 3],
    origin: [f64; MAX_MOTORS],
    target: [f64; MAX_MOTORS],
    /// Counts per normalised unit of position.
    length: f64,
    /// Seconds per normalised unit of time.
    tau: f64,
    /// Seconds; 0 when the profile is a rest at its target.
    duration: f64,
}

impl Profile {
    /// A planner for `n` motors, at rest at `p`.
    pub fn new(n: usize, p: [f64; MAX_MOTORS]) -> Profile {
        let zeros = || DataArrayOrVec::<f64, MAX_MOTORS>::new(None, 0.0);
        Profile {
            n: n.min(MAX_MOTORS),
            otg: Ruckig::new(None, 1.0),
            input: InputParameter::new(None),
            trajectory: Trajectory::new(None),
            at: [zeros(), zeros(), zeros()],
            origin: p,
            target: p,
            length: 1.0,
            tau: 1.0,
            duration: 0.0,
        }
    }

    /// Plans the move from `from` to rest at `to` under `limits`. On an error the planner
    /// holds what it had. Allocates nothing unless Ruckig fails (its message).
    pub fn plan(
        &mut self,
        from: &MotionState,
        to: &[f64; MAX_MOTORS],
        limits: &MotionLimits,
    ) -> Result<(), NoProfile> {
        self.solve(from, Some(to), limits)
    }

    /// Plans the quickest jerk-limited stop from `from` to rest wherever it comes, every
    /// motor stopping together (Ruckig's velocity interface, to 0). Allocates nothing unless
    /// Ruckig fails.
    pub fn plan_stop(
        &mut self,
        from: &MotionState,
        limits: &MotionLimits,
    ) -> Result<(), NoProfile> {
        self.solve(from, None, limits)
    }

    fn solve(
        &mut self,
        from: &MotionState,
        to: Option<&[f64; MAX_MOTORS]>,
        limits: &MotionLimits,
    ) -> Result<(), NoProfile> {
        let n = self.n;
        // A stop goes where the motion carries it: its distance is that of the velocity.
        let stop = to.is_none();
        let to = to.copied().unwrap_or(from.p);
        let (vl, al, jl) = (&limits.velocity, &limits.acceleration, &limits.jerk);
        let finite = (0..n).all(|m| {
            [from.p[m], from.v[m], from.a[m], to[m]].iter().all(|x| x.is_finite())
                && [vl[m], al[m], jl[m]].iter().all(|x| x.is_finite() && *x > 0.0)
        });
        if !finite {
            return Err(NoProfile);
        }
        // The time scale: the slowest motor's rest-to-rest time plus the time to take away
        // its velocity and acceleration; the length scale: the largest of the distances and
        // of what the velocity and acceleration carry over that time.
        let tau = (0..n)
            .map(|m| {
                double_s_duration(to[m] - from.p[m], vl[m], al[m], jl[m])
                    + from.v[m].abs() / al[m]
                    + from.a[m].abs() / jl[m]
            })
            .fold(0.0, f64::max);
        let length = (0..n)
            .map(|m| {
                (to[m] - from.p[m])
                    .abs()
                    .max(from.v[m].abs() * tau)
                    .max(from.a[m].abs() * tau * tau)
            })
            .fold(0.0, f64::max);
        if !(tau > 0.0 && length > 0.0) {
            // At rest on the target already.
            self.origin = to;
            self.target = to;
            self.duration = 0.0;
            return Ok(());
        }
        let inp = &mut self.input;
        inp.control_interface =
            if stop { ControlInterface::Velocity } else { ControlInterface::Position };
        for m in 0..MAX_MOTORS {
            let used = m < n;
            let k = |x: f64| if used { x } else { 0.0 };
            inp.current_position[m] = 0.0;
            inp.current_velocity[m] = k(from.v[m] * tau / length);
            inp.current_acceleration[m] = k(from.a[m] * tau * tau / length);
            inp.target_position[m] = k((to[m] - from.p[m]) / length);
            inp.target_velocity[m] = 0.0;
            inp.target_acceleration[m] = 0.0;
            inp.max_velocity[m] = if used { vl[m] * tau / length } else { 1.0 };
            inp.max_acceleration[m] = if used { al[m] * tau * tau / length } else { 1.0 };
            inp.max_jerk[m] = if used { jl[m] * tau * tau * tau / length } else { 1.0 };
        }
        self.otg.calculate(&self.input, &mut self.trajectory).map_err(|_| NoProfile)?;
        let duration = self.trajectory.get_duration() * tau;
        if !duration.is_finite() {
            return Err(NoProfile);
        }
        self.origin = from.p;
        self.length = length;
        self.tau = tau;
        self.duration = duration;
        self.target = to;
        if stop {
            // Where the stop comes to rest: the profile's end, sampled (not the target, which
            // `state_at` returns from there on and which this sets).
            self.target = self.sample(duration).p;
        }
        Ok(())
    }

    /// The profile's duration, s (0: at rest on its target).
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// The target, counts.
    pub fn target(&self) -> &[f64; MAX_MOTORS] {
        &self.target
    }

    /// The state `t` seconds into the profile: at `t ≥` its duration, exactly the target at
    /// rest.
    pub fn state_at(&mut self, t: f64) -> MotionState {
        if t >= self.duration {
            return MotionState::at_rest(self.target);
        }
        self.sample(t)
    }

    /// The planned trajectory's state `t` seconds in, at any `t`.
    fn sample(&mut self, t: f64) -> MotionState {
        let [p, v, a] = &mut self.at;
        let mut section = None;
        self.trajectory.at_time(
            t.max(0.0) / self.tau,
            &mut Some(p),
            &mut Some(v),
            &mut Some(a),
            &mut None,
            &mut section,
        );
        let (length, tau) = (self.length, self.tau);
        let mut s = MotionState::at_rest(self.origin);
        for m in 0..self.n {
            s.p[m] = self.origin[m] + self.at[0][m] * length;
            s.v[m] = self.at[1][m] * length / tau;
            s.a[m] = self.at[2][m] * length / (tau * tau);
        }
        s
    }

    /// Each motor's smallest and largest position over the profile, counts: exactly, from
    /// its segments (Ruckig's own `get_position_extrema` misses an extremum inside a segment
    /// of constant acceleration — where a motor moving away from its target turns round).
    pub fn bounds(&self) -> [(f64, f64); MAX_MOTORS] {
        let mut b = [(0.0, 0.0); MAX_MOTORS];
        for (m, bm) in b.iter_mut().enumerate() {
            *bm = (self.target[m], self.target[m]);
        }
        if self.duration == 0.0 {
            return b;
        }
        for (m, bm) in b.iter_mut().enumerate().take(self.n) {
            let pr = &self.trajectory.profiles[0][m];
            let mut ext = (self.origin[m], self.origin[m]);
            let (o, l) = (self.origin[m], self.length);
            let mut segment = |t: f64, p: f64, v: f64, a: f64, j: f64| {
                segment_extrema(&mut ext, t, o + p * l, v * l, a * l, j * l);
            };
            if pr.brake.duration > 0.0 {
                for k in 0..2 {
                    let br = &pr.brake;
                    segment(br.t[k], br.p[k], br.v[k], br.a[k], br.j[k]);
                }
            }
            for k in 0..7 {
                segment(pr.t[k], pr.p[k], pr.v[k], pr.a[k], pr.j[k]);
            }
            *bm = (ext.0.min(bm.0), ext.1.max(bm.1));
        }
        b
    }
}

/// Widens `ext` to the positions of one constant-jerk segment of `t` (normalised time units;
/// positions already in counts, its velocity, acceleration and jerk in counts per normalised
/// unit): its start, its end and where its velocity passes 0 inside it.
fn segment_extrema(ext: &mut (f64, f64), t: f64, p: f64, v: f64, a: f64, j: f64) {
    let at = |x: f64| p + x * (v + x * (a / 2.0 + x * j / 6.0));
    let mut take = |x: f64| {
        if x.is_finite() && (0.0..=t).contains(&x) {
            let q = at(x);
            *ext = (ext.0.min(q), ext.1.max(q));
        }
    };
    take(0.0);
    take(t);
    if j != 0.0 {
        let d = a * a - 2.0 * j * v;
        if d >= 0.0 {
            take((-a - d.sqrt()) / j);
            take((-a + d.sqrt()) / j);
        }
    } else if a != 0.0 {
        take(-v / a);
    }
}

/// The worst ratio of `queue`'s sampled motion (one sample every `period_s`, at rest before
/// its first sample and after its last) to `limits`, over its first `n` motors, as a time
/// scale: max(v/v_max, √(a/a_max), ∛(j/j_max)) of the backward differences. Playing the queue
/// k times as fast multiplies it by k; ≤ 1 keeps every limit.
pub fn sampled_ratio(
    queue: &[[f64; MAX_MOTORS]],
    n: usize,
    period_s: f64,
    limits: &MotionLimits,
) -> f64 {
    let Some(last) = queue.len().checked_sub(1) else { return 0.0 };
    let t = period_s;
    let mut worst: f64 = 0.0;
    for i in 0..queue.len() + 3 {
        let q = |back: usize, m: usize| queue[i.saturating_sub(back).min(last)][m];
        for m in 0..n.min(MAX_MOTORS) {
            let (q0, q1, q2, q3) = (q(0, m), q(1, m), q(2, m), q(3, m));
            let v = (q0 - q1) / t;
            let a = (q0 - 2.0 * q1 + q2) / (t * t);
            let j = (q0 - 3.0 * q1 + 3.0 * q2 - q3) / (t * t * t);
            worst = worst
                .max(v.abs() / limits.velocity[m])
                .max((a.abs() / limits.acceleration[m]).sqrt())
                .max((j.abs() / limits.jerk[m]).cbrt());
        }
    }
    worst
}
