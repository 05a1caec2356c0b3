//! `move --xyz X,Y,Z --linear`: a straight line in Cartesian space from where the effector
//! is to the point, jerk-limited along the line, every joint within its limits.
//!
//! The way along the line, s from 0 to 1, is one jerk-limited rest-to-rest profile (Ruckig,
//! [`Profile`]); the joints follow it through the inverse kinematics, so every sample is on
//! the line. The joints' velocity, acceleration and jerk are those of s times the line's
//! geometry (dq/ds, d²q/ds², d³q/ds³), which the profile's limits do not see; so the profile
//! is time-scaled until the sampled commands' worst ratio to the joint limits is just below
//! 1 — playing a profile k times as fast multiplies every joint's velocity by k, its
//! acceleration by k² and its jerk by k³, exactly.

use crate::motion::{MotionLimits, MotionState, Profile, sampled_ratio};
use crate::source::{CommandQueue, QUEUE_BUDGET_BYTES, TrajBuildError};
use qmarc_config::{MoveTarget, Settings};
use qmarc_controller::traj::{TrajStartError, TrajectoryGenerator};
use qmarc_kinematics::{ARMS, Point, Robot};
use qmarc_proto::{MAX_MOTORS, MotorFlags};

/// How close to the joint limits the line is played: the worst sampled ratio lands in
/// `[LINE_FILL, 1]`.
pub const LINE_FILL: f64 = 0.98;

/// Points along the line at which its reach and geometry are checked before the profile.
const LINE_POINTS: usize = 400;

/// The straight-line move of the settings' `move --xyz … --linear`.
pub struct LinearMove {
    robot: Robot,
    to_mm: [f64; 3],
    /// A Cartesian jog (`Some`): `to_mm` is a distance from where the effector is, not a
    /// point, and the robot's frame must be homed — whether it is, `observe` sees.
    jog: Option<bool>,
    period_s: f64,
    limits: MotionLimits,
    queue: CommandQueue,
}

impl LinearMove {
    /// A line to `to_mm` for `robot`, under `limits`, one sample every `period_s`.
    pub fn new(robot: Robot, to_mm: [f64; 3], period_s: f64, limits: MotionLimits) -> LinearMove {
        LinearMove { robot, to_mm, jog: None, period_s, limits, queue: CommandQueue::default() }
    }

    /// The Cartesian jog of the settings (`jog --axis A --mm D`): the effector `jog.mm` along
    /// the axis from where it is, a straight line at `jog.speed` of the motors' limits, in
    /// the homed frame only.
    pub fn jog(s: &Settings) -> Result<LinearMove, TrajBuildError> {
        let axis = s.jog.axis.unwrap_or(0).min(2);
        let mut by = [0.0; 3];
        by[axis] = s.jog.mm;
        let limits = MotionLimits::of(s).at_speed(s.jog.speed);
        let line = LinearMove::new(robot_of(s)?, by, s.period_s(), limits);
        Ok(LinearMove { jog: Some(false), ..line })
    }

    /// The line of the settings' `move` target at its `--speed`.
    pub fn from_settings(s: &Settings) -> Result<LinearMove, TrajBuildError> {
        let MoveTarget::Xyz { mm, .. } = s.motion.target else {
            return Err(TrajBuildError::Line("a straight line needs an --xyz target".into()));
        };
        let limits = MotionLimits::of(s).at_speed(s.motion.speed);
        Ok(LinearMove::new(robot_of(s)?, mm, s.period_s(), limits))
    }

    /// After [`TrajectoryGenerator::start`]: its samples, one per period.
    pub fn into_queue(self) -> Vec<[f64; MAX_MOTORS]> {
        self.queue.into_commands()
    }

    /// The joint counts of the line's point at `s` (0‥1) from `a` to `b`, m.
    fn counts_at(&self, a: &Point, b: &Point, s: f64) -> Result<[f64; MAX_MOTORS], String> {
        let p = a + (b - a) * s;
        let c = self.robot.counts_of(&p).map_err(|e| {
            format!(
                "the line leaves the workspace at {:.1}, {:.1}, {:.1} mm: {e}",
                p.x * 1e3,
                p.y * 1e3,
                p.z * 1e3
            )
        })?;
        let mut q = [0.0; MAX_MOTORS];
        q[..ARMS].copy_from_slice(&c);
        Ok(q)
    }

    /// The line from `start` (counts) sampled into the command queue.
    fn plan(&self, start: &[f64; MAX_MOTORS]) -> Result<Vec<[f64; MAX_MOTORS]>, String> {
        let mut here = [0.0; ARMS];
        here.copy_from_slice(&start[..ARMS]);
        let a = self.robot.point_of(&here).map_err(|e| format!("where the effector is: {e}"))?;
        let [x, y, z] = self.to_mm;
        let mut b = Point::new(x / 1e3, y / 1e3, z / 1e3);
        if self.jog.is_some() {
            b += a;
        }
        if (b - a).norm() < 1e-9 {
            return Ok(vec![*start]);
        }
        // The largest |dq/ds| of each joint along the line gives the profile's first limits.
        let mut slope = [0.0f64; MAX_MOTORS];
        let mut prev = *start;
        for i in 1..=LINE_POINTS {
            let q = self.counts_at(&a, &b, i as f64 / LINE_POINTS as f64)?;
            for m in 0..ARMS {
                slope[m] = slope[m].max((q[m] - prev[m]).abs() * LINE_POINTS as f64);
            }
            prev = q;
        }
        let l = &self.limits;
        let s_limit = |lim: &[f64; MAX_MOTORS]| {
            (0..ARMS).map(|m| lim[m] / slope[m].max(1e-9)).fold(f64::INFINITY, f64::min)
        };
        let base = (s_limit(&l.velocity), s_limit(&l.acceleration), s_limit(&l.jerk));
        let mut k = 1.0;
        for _ in 0..12 {
            let queue = self.sampled(start, &a, &b, base, k)?;
            let r = sampled_ratio(&queue, ARMS, self.period_s, l);
            if r <= 1.0 && (r >= LINE_FILL || queue.len() <= 4) {
                return Ok(queue);
            }
            k *= (LINE_FILL + 1.0) / 2.0 / r;
        }
        Err("no time scaling of the line keeps every joint within its limits".into())
    }

    /// The line's profile with the s-limits `base` played `k` times as fast, sampled.
    fn sampled(
        &self,
        start: &[f64; MAX_MOTORS],
        a: &Point,
        b: &Point,
        base: (f64, f64, f64),
        k: f64,
    ) -> Result<Vec<[f64; MAX_MOTORS]>, String> {
        let one = |x: f64| {
            let mut v = [1.0; MAX_MOTORS];
            v[0] = x;
            v
        };
        let limits = MotionLimits {
            velocity: one(base.0 * k),
            acceleration: one(base.1 * k * k),
            jerk: one(base.2 * k * k * k),
        };
        let mut profile = Profile::new(1, [0.0; MAX_MOTORS]);
        let mut to = [0.0; MAX_MOTORS];
        to[0] = 1.0;
        profile
            .plan(&MotionState::default(), &to, &limits)
            .map_err(|e| format!("the line's profile: {e}"))?;
        let seconds = profile.duration();
        let samples = (seconds / self.period_s).ceil() + 1.0;
        let bytes = samples * std::mem::size_of::<[f64; MAX_MOTORS]>() as f64;
        if !seconds.is_finite() || bytes > QUEUE_BUDGET_BYTES as f64 {
            return Err(format!("the line takes {seconds:.1} s: more than the queue may hold"));
        }
        let mut queue = Vec::with_capacity(samples as usize);
        queue.push(*start);
        for i in 1..samples as u64 {
            let s = profile.state_at(i as f64 * self.period_s).p[0];
            queue.push(self.counts_at(a, b, s)?);
        }
        Ok(queue)
    }
}

/// The robot of the settings, or why a line cannot be made.
fn robot_of(s: &Settings) -> Result<Robot, TrajBuildError> {
    s.robot().ok_or_else(|| {
        TrajBuildError::Line(format!(
            "{} has no [robot] table for 3 motors: a line needs the Delta's geometry",
            s.source.display()
        ))
    })
}

impl TrajectoryGenerator for LinearMove {
    fn name(&self) -> &'static str {
        if self.jog.is_some() { "jog" } else { "linear" }
    }

    /// A jog's robot must be homed: the first observation (before `start`) says.
    #[inline]
    fn observe(&mut self, _: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        if self.jog == Some(false) && flags[..ARMS].iter().all(|f| f.homed()) {
            self.jog = Some(true);
        }
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        if self.jog == Some(false) {
            return Err(TrajStartError::Generator(Box::new(TrajBuildError::Line(
                "a Cartesian jog moves in the homed frame: home the robot first (qmarc-starter \
                 home), or jog one motor (--motor, --counts)"
                    .into(),
            ))));
        }
        let queue = self
            .plan(start)
            .map_err(|e| TrajStartError::Generator(Box::new(TrajBuildError::Line(e))))?;
        self.queue = CommandQueue::at_rest(queue);
        Ok(())
    }

    crate::source::follows_queue!(queue, sample);
}
