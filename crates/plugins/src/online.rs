//! Online, jerk-limited moves to a target that may change while the robot moves: Ruckig's
//! time-synchronised, time-optimal profile (the `rsruckig` port) from whatever state the
//! command is in — position, velocity and acceleration of every motor — to a target at rest.
//!
//! [`Profile`] is the planner: it plans in the servo thread, allocating nothing after it is
//! built. [`OnlineMove`] is the generator of `qmarc-starter move --to/--xyz`: it samples the
//! profile every cycle, and [`OnlineMove::retarget`] replaces the target mid-motion from the
//! state of the last command sample, so position, velocity and acceleration go on without a
//! jump.

use crate::moveto::{MotionLimits, double_s_duration};
use crate::source::TrajBuildError;
use qmarc_config::Settings;
use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator};
use qmarc_proto::MAX_MOTORS;
use rsruckig::prelude::{
    ControlInterface, DataArrayOrVec, InputParameter, Ruckig, ThrowErrorHandler, Trajectory,
};

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
            // Where the stop comes to rest: the profile's end.
            self.duration = f64::INFINITY;
            self.target = self.state_at(duration).p;
            self.duration = duration;
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

/// The generator of `qmarc-starter move --to/--xyz`: from where the motors are, at rest, to
/// the target at rest, every motor starting and arriving together, the slowest as fast as
/// its limits (× `--speed`) allow. The profile is sampled in the loop, so a new target
/// ([`OnlineMove::retarget`]) takes over in the next cycle.
pub struct OnlineMove {
    profile: Profile,
    n_motors: usize,
    period_s: f64,
    limits: MotionLimits,
    target: [f64; MAX_MOTORS],
    /// The sample index the profile starts at.
    origin_n: u64,
    /// The last sample commanded and its state.
    last: (u64, MotionState),
    samples: u64,
    /// The bounds of the move planned at the start.
    bounds: Option<[(f64, f64); MAX_MOTORS]>,
    /// The planner a new target is planned into, kept only if it stays within `soft`.
    spare: Option<Box<Profile>>,
    /// The soft limits a new target's profile must keep, if any.
    soft: Option<[(f64, f64); MAX_MOTORS]>,
}

/// A new target was not taken: no profile, or one that leaves the soft limits on its way
/// (a target inside them that the motion's momentum would carry beyond).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RetargetError {
    /// Ruckig found no profile.
    #[error(transparent)]
    NoProfile(#[from] NoProfile),
    /// The profile would carry `motor` (1-based) to `counts`, outside its soft limits.
    #[error(
        "the way there would carry motor {motor} to {counts:.0} counts, outside its soft limits"
    )]
    SoftLimits {
        /// 1-based motor.
        motor: usize,
        /// Where it would go, counts.
        counts: f64,
    },
}

impl OnlineMove {
    /// A move to `target` (counts, the first `n_motors` used) under `limits`, sampled every
    /// `period_s`.
    pub fn new(
        target: [f64; MAX_MOTORS],
        n_motors: usize,
        period_s: f64,
        limits: MotionLimits,
    ) -> OnlineMove {
        OnlineMove {
            profile: Profile::new(n_motors, target),
            n_motors,
            period_s,
            limits,
            target,
            origin_n: 0,
            last: (0, MotionState::at_rest(target)),
            samples: 1,
            bounds: None,
            spare: None,
            soft: None,
        }
    }

    /// The move of the settings' `move` target at its `--speed`.
    pub fn from_settings(s: &Settings) -> Result<OnlineMove, TrajBuildError> {
        let counts = s.motion.target.counts();
        if counts.len() != s.n_motors {
            return Err(TrajBuildError::Target { positions: counts.len(), motors: s.n_motors });
        }
        let mut target = [0.0; MAX_MOTORS];
        target[..counts.len()].copy_from_slice(counts);
        let limits = MotionLimits::of(s).at_speed(s.motion.speed);
        Ok(OnlineMove::new(target, s.n_motors, s.period_s(), limits))
    }

    /// Every new target's profile must keep within `soft` (per motor, counts): one that would
    /// leave them is not taken ([`RetargetError::SoftLimits`]). Allocates its second planner.
    pub fn with_soft_limits(mut self, soft: [(f64, f64); MAX_MOTORS]) -> OnlineMove {
        self.soft = Some(soft);
        self.spare = Some(Box::new(Profile::new(self.n_motors, self.target)));
        self
    }

    /// Replaces the target from the next sample on: the new profile starts from the state of
    /// the last sample commanded, so the command's position, velocity and acceleration go on
    /// without a jump and the next sample is already the new profile's. Allocates nothing; on
    /// an error the move goes on as it was.
    pub fn retarget(
        &mut self,
        target: &[f64; MAX_MOTORS],
        limits: &MotionLimits,
    ) -> Result<(), RetargetError> {
        let from = self.last.1;
        self.replan(|p| p.plan(&from, target, limits))?;
        self.limits = *limits;
        Ok(())
    }

    /// A jerk-limited stop to rest from the state of the last sample commanded, every motor
    /// stopping together, as [`OnlineMove::retarget`] takes over.
    pub fn stop(&mut self, limits: &MotionLimits) -> Result<(), RetargetError> {
        let from = self.last.1;
        self.replan(|p| p.plan_stop(&from, limits))?;
        self.limits = *limits;
        Ok(())
    }

    /// Plans with `plan` (into the spare planner when the soft limits are kept, and swaps it
    /// in only if its profile keeps them) and moves on from the last sample.
    fn replan(
        &mut self,
        plan: impl Fn(&mut Profile) -> Result<(), NoProfile>,
    ) -> Result<(), RetargetError> {
        match (self.spare.as_deref_mut(), self.soft) {
            (Some(spare), Some(soft)) => {
                plan(spare)?;
                let b = spare.bounds();
                // The extrema come out of normalised units: a target on a limit may read a
                // rounding beyond it.
                let (lo, hi) =
                    (|m: usize| soft[m].0 - BOUND_ROUNDING, |m: usize| soft[m].1 + BOUND_ROUNDING);
                if let Some(m) = (0..self.n_motors).find(|&m| b[m].0 < lo(m) || b[m].1 > hi(m)) {
                    let counts = if b[m].0 < soft[m].0 { b[m].0 } else { b[m].1 };
                    return Err(RetargetError::SoftLimits { motor: m + 1, counts });
                }
                std::mem::swap(&mut self.profile, spare);
            }
            _ => plan(&mut self.profile)?,
        }
        let n_last = self.last.0;
        self.target = *self.profile.target();
        self.origin_n = n_last;
        self.samples = n_last + self.samples_of(self.profile.duration());
        Ok(())
    }

    /// From sample `n` on, the command continues from `state` (a move that another generator
    /// commanded until then): a target or a stop takes over from it; without one the command
    /// holds its position.
    pub fn continue_from(&mut self, n: u64, state: MotionState) {
        self.last = (n, state);
        self.target = state.p;
        self.origin_n = n;
        self.samples = n + 1;
        let _ = self.profile.plan(&MotionState::at_rest(state.p), &state.p, &self.limits);
    }

    /// The target, counts.
    pub fn target(&self) -> &[f64; MAX_MOTORS] {
        &self.target
    }

    /// The last sample commanded and its state.
    pub fn last(&self) -> (u64, MotionState) {
        self.last
    }

    /// True while the command moves (before the profile's last sample).
    pub fn moving(&self) -> bool {
        self.last.0 + 1 < self.samples
    }

    /// The number of samples of a profile of `duration` s from its sample 0: the last one
    /// at or after its end.
    fn samples_of(&self, duration: f64) -> u64 {
        (duration / self.period_s - 1e-9).ceil().max(0.0) as u64 + 1
    }

    /// The profile's duration, s.
    pub fn duration(&self) -> f64 {
        self.profile.duration()
    }
}

impl TrajectoryGenerator for OnlineMove {
    fn name(&self) -> &'static str {
        "move"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        let from = MotionState::at_rest(*start);
        self.last = (0, from);
        self.profile = Profile::new(self.n_motors, *start);
        let (target, limits) = (self.target, self.limits);
        self.retarget(&target, &limits).map_err(|e| TrajStartError::Generator(Box::new(e)))?;
        let mut b = self.profile.bounds();
        for (bm, &s) in b.iter_mut().zip(start).take(self.n_motors) {
            *bm = (bm.0.min(s), bm.1.max(s));
        }
        self.bounds = Some(b);
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        Some(self.samples)
    }

    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        self.bounds
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.0; MAX_MOTORS])
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n >= self.samples {
            return Sample::Done;
        }
        // The last sample is the target at rest, exactly (its time may fall a rounding short
        // of the profile's end).
        let state = if n + 1 == self.samples {
            MotionState::at_rest(self.target)
        } else {
            self.profile.state_at(n.saturating_sub(self.origin_n) as f64 * self.period_s)
        };
        self.last = (n, state);
        *cmd = state.p;
        Sample::Ready
    }
}

#[cfg(test)]
mod tests;
