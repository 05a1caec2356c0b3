//! Jerk-limited moves from rest to rest: the approach to a path's start ([`Approach`]) and
//! jog ([`Jog`]). Each is Ruckig's time-synchronised, time-optimal profile (the `rsruckig`
//! port): every motor starts and arrives together, the slowest one as fast as its velocity,
//! acceleration and jerk limits allow, the others slower. It is planned before the move and
//! sampled into the command queue, so the loop only reads the queue.

use crate::motion::{MotionLimits, MotionState, Profile};
use crate::source::{CommandQueue, QUEUE_BUDGET_BYTES, TrajBuildError, sample_queue};
use qmarc_config::Settings;
use qmarc_controller::traj::{
    GeneratorReport, Sample, TrajStartError, TrajectoryGenerator, bounds_of,
};
use qmarc_proto::state::FaultKind;
use qmarc_proto::{MAX_MOTORS, MotorFlags};

/// A jerk-limited move could not be planned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MoveToError {
    /// Ruckig found no profile (a limit that is not a positive finite number, or a distance
    /// beyond what it can compute).
    #[error("no jerk-limited move from {from:?} to {to:?} counts: {reason}")]
    NoProfile {
        /// Where the motors are, counts.
        from: Vec<f64>,
        /// Where they are to go, counts.
        to: Vec<f64>,
        /// Ruckig's reason.
        reason: String,
    },
    /// The move would last longer than its command queue may.
    #[error(
        "the move from {from:?} to {to:?} counts takes {seconds:.1} s at this speed: more \
         samples than the command queue's memory budget"
    )]
    TooLong {
        /// Where the motors are, counts.
        from: Vec<f64>,
        /// Where they are to go, counts.
        to: Vec<f64>,
        /// Its duration, s.
        seconds: f64,
    },
}

impl From<MoveToError> for TrajStartError {
    fn from(e: MoveToError) -> Self {
        TrajStartError::Generator(Box::new(e))
    }
}

/// The way to a path's first knot `to` from `from`: [`rest_to_rest`] without its last
/// sample, which is the path's first (`run --approach`, `qmarc cmd path --approach`).
pub fn approach_queue(
    from: &[f64; MAX_MOTORS],
    to: &[f64; MAX_MOTORS],
    n_motors: usize,
    limits: &MotionLimits,
    period_s: f64,
) -> Result<Vec<[f64; MAX_MOTORS]>, MoveToError> {
    let mut way = rest_to_rest(from, to, n_motors, limits, period_s)?;
    way.pop();
    Ok(way)
}

/// The command queue of the move of the first `n_motors` from `from` to `to`, at rest at both
/// ends, under `limits`, one sample every `period_s`: sample 0 is `from`, the last is exactly
/// `to` (a move of no distance is that one sample). Planned by the online generator's
/// [`Profile`] (Ruckig, normalised), sampled before the move.
pub fn rest_to_rest(
    from: &[f64; MAX_MOTORS],
    to: &[f64; MAX_MOTORS],
    n_motors: usize,
    limits: &MotionLimits,
    period_s: f64,
) -> Result<Vec<[f64; MAX_MOTORS]>, MoveToError> {
    let n = n_motors.min(MAX_MOTORS);
    let (from_v, to_v) = (from[..n].to_vec(), to[..n].to_vec());
    let mut profile = Profile::new(n, *from);
    profile.plan(&MotionState::at_rest(*from), to, limits).map_err(|e| {
        let (v, a, j) = (limits.velocity, limits.acceleration, limits.jerk);
        MoveToError::NoProfile {
            from: from_v.clone(),
            to: to_v.clone(),
            reason: format!("{e} under the limits {v:?}, {a:?}, {j:?} counts/s, /s², /s³"),
        }
    })?;
    let seconds = profile.duration();
    let samples = (seconds / period_s).ceil();
    let bytes = (samples + 1.0) * std::mem::size_of::<[f64; MAX_MOTORS]>() as f64;
    if !seconds.is_finite() || bytes > QUEUE_BUDGET_BYTES as f64 {
        return Err(MoveToError::TooLong { from: from_v, to: to_v, seconds });
    }
    let mut queue = Vec::with_capacity(samples as usize + 1);
    queue.push(*from);
    for k in 1..samples as u64 {
        let mut cmd = *from;
        cmd[..n].copy_from_slice(&profile.state_at(k as f64 * period_s).p[..n]);
        queue.push(cmd);
    }
    if seconds > 0.0 {
        let mut last = *from;
        last[..n].copy_from_slice(&to[..n]);
        queue.push(last);
    }
    Ok(queue)
}

/// Jog (`qmarc-starter jog --motor M --counts N`): motor M moves N counts from where it is,
/// the others hold, jerk-limited at `[jog] speed` of the motor's limits — or at
/// `unhomed_speed` when its frame is not homed (then nothing says where its switches are).
/// The software limits hold where it is homed (the loop checks them).
///
/// It watches the limit switches itself, as homing does (the hwserver's latch would refuse a
/// motor resting on one): a motor resting on a switch may be jogged away from it, not toward
/// it, and any switch that becomes active during the jog — or comes back after it cleared —
/// ends it in `limit_switch`.
#[derive(Debug, Clone)]
pub struct Jog {
    motor: usize,
    counts: f64,
    n_motors: usize,
    period_s: f64,
    limits: MotionLimits,
    speed: f64,
    unhomed_speed: f64,
    homed: bool,
    queue: CommandQueue,
    /// Per motor, the way to its top switch in counts (−1 or +1).
    top_direction: [f64; MAX_MOTORS],
    /// Per motor, the switches active since the jog began and continuously since.
    resting: [MotorFlags; MAX_MOTORS],
    observed: bool,
    /// A switch that tripped during the jog: its motor and whether it is the top one.
    tripped: Option<(usize, bool)>,
}

impl Jog {
    /// The jog of the settings' `[jog]`: motor `jog.motor` by `jog.counts`.
    pub fn from_settings(s: &Settings) -> Result<Jog, TrajBuildError> {
        let mut top_direction = [-1.0; MAX_MOTORS];
        for (t, safety) in top_direction.iter_mut().zip(&s.safety) {
            *t = safety.top_direction;
        }
        Ok(Jog {
            motor: s.jog.motor - 1,
            counts: s.jog.counts as f64,
            n_motors: s.n_motors,
            period_s: s.period_s(),
            limits: MotionLimits::of(s),
            speed: s.jog.speed,
            unhomed_speed: s.jog.unhomed_speed,
            homed: false,
            queue: CommandQueue::default(),
            top_direction,
            resting: [MotorFlags::default(); MAX_MOTORS],
            observed: false,
            tripped: None,
        })
    }

    /// Why it failed, in words, after a failed sample.
    pub fn failure(&self) -> Option<String> {
        self.tripped.map(|(k, top)| {
            format!(
                "jog: motor {}'s {} limit switch tripped (it was not active when the jog began)",
                k + 1,
                if top { "top" } else { "bottom" }
            )
        })
    }
}

impl TrajectoryGenerator for Jog {
    fn name(&self) -> &'static str {
        "jog"
    }

    /// Before `start`: whether the jogged motor's frame is homed (its speed) and which
    /// switches the motors rest on; then every cycle, a switch that was not resting tripping.
    #[inline]
    fn observe(&mut self, _: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        if !self.observed {
            self.homed = flags[self.motor].homed();
            self.resting = *flags;
            self.observed = true;
            return;
        }
        for (k, (r, f)) in self.resting.iter_mut().zip(flags).enumerate().take(self.n_motors) {
            *r = MotorFlags(r.0 & f.0);
            if self.tripped.is_none() && (f.top() && !r.top() || f.bottom() && !r.bottom()) {
                self.tripped = Some((k, f.top() && !r.top()));
            }
        }
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        let (m, rest) = (self.motor, self.resting[self.motor]);
        let toward_top = self.counts * self.top_direction[m] > 0.0;
        if (rest.top() && toward_top) || (rest.bottom() && !toward_top) {
            return Err(TrajStartError::Generator(
                format!(
                    "motor {} rests on its {} limit switch: jog it away from the switch \
                     (--counts of the other sign)",
                    m + 1,
                    if rest.top() { "top" } else { "bottom" }
                )
                .into(),
            ));
        }
        self.tripped = None;
        let mut to = *start;
        to[self.motor] += self.counts;
        let speed = if self.homed { self.speed } else { self.unhomed_speed };
        let limits = self.limits.at_speed(speed);
        self.queue =
            CommandQueue::at_rest(rest_to_rest(start, &to, self.n_motors, &limits, self.period_s)?);
        Ok(())
    }

    crate::source::follows_queue!(queue);

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if self.tripped.is_some() {
            return Sample::Failed;
        }
        self.queue.sample(n, cmd)
    }

    fn failure_kind(&self) -> FaultKind {
        FaultKind::LimitSwitch
    }

    fn report(&self) -> GeneratorReport {
        GeneratorReport { failure: self.failure(), ..GeneratorReport::default() }
    }
}

/// A path with the way to its start in front of it (`run --approach`): from where the motors
/// are, a jerk-limited move at `trajectory.approach_speed` of their limits to the path's first
/// command, then the path. Its samples before the path are the [`TrajectoryGenerator::lead_in`]
/// the loop reports apart from the path's error figures.
pub struct Approach {
    path: Box<dyn TrajectoryGenerator>,
    n_motors: usize,
    period_s: f64,
    limits: MotionLimits,
    lead: Vec<[f64; MAX_MOTORS]>,
}

impl Approach {
    /// `path`, approached from where the motors are at `speed` of `limits`.
    pub fn new(
        path: Box<dyn TrajectoryGenerator>,
        n_motors: usize,
        period_s: f64,
        limits: MotionLimits,
    ) -> Approach {
        Approach { path, n_motors, period_s, limits, lead: Vec::new() }
    }

    /// The approach of the settings (`trajectory.approach_speed`) to `path`.
    pub fn from_settings(path: Box<dyn TrajectoryGenerator>, s: &Settings) -> Approach {
        let limits = MotionLimits::of(s).at_speed(s.trajectory.approach_speed);
        Approach::new(path, s.n_motors, s.period_s(), limits)
    }

    fn lead_samples(&self) -> u64 {
        self.lead.len() as u64
    }
}

impl TrajectoryGenerator for Approach {
    fn name(&self) -> &'static str {
        self.path.name()
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        let Some(first) = self.path.first_command()? else {
            self.lead.clear();
            return self.path.start(start);
        };
        self.lead = approach_queue(start, &first, self.n_motors, &self.limits, self.period_s)?;
        self.path.start(&first)
    }

    fn samples(&self) -> Option<u64> {
        self.path.samples().map(|s| s + self.lead_samples())
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        match n.checked_sub(self.lead_samples()) {
            None => sample_queue(&self.lead, n, cmd),
            Some(k) => self.path.sample(k, cmd),
        }
    }

    fn failure_kind(&self) -> FaultKind {
        self.path.failure_kind()
    }

    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        self.path.observe(act, flags);
    }

    /// The way there's bounds with the path's; the way there's alone before a stream (whose
    /// commands the loop checks as they come): the approach never runs unchecked.
    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        let lead = bounds_of(&self.lead);
        let Some(path) = self.path.path_bounds() else { return Some(lead) };
        Some(std::array::from_fn(|m| (path[m].0.min(lead[m].0), path[m].1.max(lead[m].1))))
    }

    #[inline]
    fn progress(&self) -> u32 {
        self.path.progress()
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        self.path.end_velocity()
    }

    fn report(&self) -> GeneratorReport {
        self.path.report()
    }

    fn lead_in(&self) -> u64 {
        self.lead_samples()
    }
}

#[cfg(test)]
mod tests;
