//! Online, jerk-limited moves to a target that may change while the robot moves: the
//! [`motion`](crate::motion) planner's profile from whatever state the command is in —
//! position, velocity and acceleration of every motor — to a target at rest.
//!
//! [`OnlineMove`] is the generator of `qmarc-starter move --to/--xyz`: it samples the
//! profile every cycle, and [`OnlineMove::retarget`] replaces the target mid-motion from the
//! state of the last command sample, so position, velocity and acceleration go on without a
//! jump.

use crate::motion::{BOUND_ROUNDING, MotionLimits, MotionState, NoProfile, Profile};
use crate::source::TrajBuildError;
use qmarc_config::Settings;
use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator};
use qmarc_proto::MAX_MOTORS;

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
