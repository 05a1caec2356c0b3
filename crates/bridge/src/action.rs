//! `NS/qmarc/follow_joint_trajectory`: the `control_msgs/action/FollowJointTrajectory` server
//! MoveIt drives arms with, as rcl_action lays an action out on rmw_zenoh — three services
//! (`_action/send_goal`, `_action/cancel_goal`, `_action/get_result`) and two topics
//! (`_action/feedback`, `_action/status`; the status on every change, transient local: a
//! client that joins later gets the last from the publisher's cache).
//!
//! A goal is the path of its trajectory (`qmarc/path`, as `qmarc/joint_trajectory` sends it):
//! accepted when the controller takes the path, rejected with the reason logged and in
//! `/diagnostics` when it or the bridge refuses it, or while another goal runs. While it
//! runs, the feedback is the loop's command (desired), the motors (actual) and their
//! difference, from the telemetry. A joint further from its command than its path tolerance
//! in any telemetry sample the bridge receives (however late it turns: the telemetry queues
//! 1024 samples, 1.6 s by default), or off its command's velocity by more than its tolerance
//! (in any sample too, over the 20 ms before it), stops the robot and aborts the goal
//! (`PATH_TOLERANCE_VIOLATED`). Once the command rests at the path's end, in the status and
//! in the telemetry, each joint has `goal_time_tolerance` to be within its goal tolerance
//! (position from the end, velocity from rest; `GOAL_TOLERANCE_VIOLATED` if not). A bound
//! of 0 or −1 (or none given) is not checked, and acceleration bounds never are. A cancel
//! stops the robot (jerk-limited) and the goal ends canceled once it rests; a fault, the
//! session's end or another motion (a move, a stop — a grip on the way is none) ends it
//! aborted. A `goal_time_tolerance` of 0 is [`DEFAULT_GOAL_TIME`].
//!
//! This module is the goal tracker alone, without I/O ([`GoalTracker`]): it is told what
//! arrived (a goal, a cancel, a request for a result, the loop's status, the telemetry) and
//! answers what is to be done (send the path, send a stop, publish feedback or the goals'
//! status, answer the clients waiting for a result); the bridge's loop does it.

use crate::action_msgs::{
    CancelGoalResponse, FeedbackMessage, FjtFeedback, FjtResult, GetResultResponse, GoalInfo,
    GoalStatus, GoalStatusArray, JointTolerance, SendGoalRequest, Uuid,
};
use crate::convert::{Converter, rate, seconds_between};
use crate::msgs::{Header, JointTrajectoryPoint, Time};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_session::client::{Fate, OrderLedger};
use qmarc_session::wire::{CommandResponse, PathRequest};
use std::time::{Duration, Instant};

/// Ended goals the server still answers for (the oldest forgotten first).
const KEPT_GOALS: usize = 16;

/// How long after the path's end the joints have to be within the goal tolerance when the
/// goal leaves `goal_time_tolerance` 0 (the server's default, as the message's comment says).
pub const DEFAULT_GOAL_TIME: Duration = Duration::from_secs(1);

/// How near the path's end (counts) a sample's command is at it: the loop's last sample of a
/// path is the end's numbers exactly.
const END_MATCH_COUNTS: f64 = 1e-6;

/// Feedback messages a second, at most.
const FEEDBACK_HZ: f64 = 50.0;

/// Where each motor is and how fast it goes: counts and counts/s.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Motion {
    /// Counts.
    pub position: [f64; MAX_MOTORS],
    /// Counts/s.
    pub velocity: [f64; MAX_MOTORS],
}

/// A running goal's bounds on how far the motors may be from where they should be and how
/// fast they should go (counts, counts/s), per motor (0: unchecked).
type Tolerances = Motion;

impl Motion {
    /// At `position`, at rest.
    fn at(position: [f64; MAX_MOTORS]) -> Motion {
        Motion { position, ..Motion::default() }
    }

    /// As two tolerances: its positions alone, and its velocities alone.
    fn split(&self) -> (Tolerances, Tolerances) {
        (Motion::at(self.position), Motion { velocity: self.velocity, ..Motion::default() })
    }
}

/// What of a motor is beyond its tolerance: the motor (0-based), "position" or "velocity",
/// how far it is and the tolerance (counts or counts/s).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Violation {
    motor: usize,
    what: &'static str,
    off: f64,
    tolerance: f64,
}

impl Violation {
    /// Its words, in rad (rad/s) through `per_rad` counts a radian.
    fn words(&self, per_rad: f64) -> String {
        let unit = if self.what == "velocity" { "rad/s" } else { "rad" };
        format!(
            "motor{}'s {} is {:.5} {unit} off (tolerance {:.5} {unit})",
            self.motor + 1,
            self.what,
            self.off / per_rad,
            self.tolerance / per_rad
        )
    }
}

/// The first motor (of `n`) whose position, then velocity, is further from `want` than its
/// tolerance in `tol` (0: unchecked).
fn beyond(tol: &Tolerances, want: &Motion, got: &Motion, n: usize) -> Option<Violation> {
    let kinds = [
        ("position", &tol.position, &want.position, &got.position),
        ("velocity", &tol.velocity, &want.velocity, &got.velocity),
    ];
    (0..n).find_map(|motor| {
        kinds.iter().find_map(|&(what, tol, want, got)| {
            let off = (want[motor] - got[motor]).abs();
            (tol[motor] > 0.0 && off > tol[motor]).then_some(Violation {
                motor,
                what,
                off,
                tolerance: tol[motor],
            })
        })
    })
}

/// The stop a cancel or a violation sent: the goal ends with `status` and `result` once the
/// robot rests.
#[derive(Debug)]
struct Stopping {
    id: u64,
    status: i8,
    result: FjtResult,
}

/// What a running goal waits for.
#[derive(Debug)]
struct Run {
    /// The controller's id of its path.
    path: u64,
    /// The stop under way, if any.
    stopping: Option<Stopping>,
    /// The first cycle whose sample came after the goal was accepted (the robot rested then,
    /// and rests until the loop takes the path).
    from_cycle: u64,
    /// The path's end, counts, at rest.
    end: Motion,
    path_tolerance: Tolerances,
    goal_tolerance: Tolerances,
    goal_time: Duration,
    /// When the command came to rest at the end.
    ended_at: Option<Instant>,
}

/// A goal the server knows.
struct Goal {
    info: GoalInfo,
    status: i8,
    result: FjtResult,
    run: Option<Run>,
}

/// A goal checked and its trajectory made a path, for the bridge to send
/// ([`GoalTracker::start`] once the controller took it).
pub struct NewGoal {
    info: GoalInfo,
    /// The goal's trajectory as the controller's path.
    pub path: Box<PathRequest>,
    path_tolerance: Tolerances,
    goal_tolerance: Tolerances,
    goal_time: Duration,
}

/// A goal that has ended: its result, for every client waiting for it.
#[derive(Debug, Clone, PartialEq)]
pub struct Finished {
    /// The goal.
    pub goal_id: Uuid,
    /// Its result, as `get_result` answers it.
    pub response: GetResultResponse,
}

/// A stop the tracker asks the bridge to send for a goal, which ends with `status` and
/// `result` once the robot rests; the bridge says how it went with
/// [`GoalTracker::stop_sent`].
#[derive(Debug)]
#[must_use]
pub struct StopFor {
    goal_id: Uuid,
    status: i8,
    result: FjtResult,
}

/// What the telemetry showed this turn.
pub struct Seen<'a> {
    /// Every sample received this turn, oldest first, each with the first of its velocity
    /// window.
    pub fresh: &'a [(TelemetrySample, TelemetrySample)],
    /// The newest sample.
    pub last: Option<&'a TelemetrySample>,
    /// The loop's command (desired) and the motors (actual) in the newest sample.
    pub motions: (Motion, Motion),
}

/// What watching the running goal asks of the bridge.
#[derive(Debug, Default)]
pub struct Watched {
    /// Feedback to publish.
    pub feedback: Option<FeedbackMessage>,
    /// A stop to send.
    pub stop: Option<StopFor>,
    /// A goal that ended.
    pub finished: Option<Finished>,
}

/// The action server's goals, without I/O.
pub struct GoalTracker {
    converter: Converter,
    goals: Vec<Goal>,
    feedback_at: Option<Instant>,
    changed: bool,
}

fn ended(status: i8) -> bool {
    matches!(status, GoalStatus::SUCCEEDED | GoalStatus::CANCELED | GoalStatus::ABORTED)
}

impl GoalTracker {
    /// No goals yet, for the robot `converter` describes.
    pub fn new(converter: Converter) -> GoalTracker {
        GoalTracker { converter, goals: Vec::new(), feedback_at: None, changed: false }
    }

    /// Whether a goal runs (the loop's status is needed to watch it).
    pub fn running(&self) -> bool {
        self.goals.iter().any(|g| g.run.is_some())
    }

    /// Goal `r`, stamped `stamp`, checked and made a path; why not, in words.
    pub fn check(&self, r: &SendGoalRequest, stamp: Time) -> Result<NewGoal, String> {
        if self.running() {
            return Err("a goal is running: cancel it first".to_string());
        }
        if self.goals.iter().any(|g| g.info.goal_id == r.goal_id) {
            return Err("a goal with this id exists".to_string());
        }
        let (path_tolerance, goal_tolerance) = self.goal_bounds(r)?;
        let path = self.converter.path(&r.goal.trajectory)?;
        let d = r.goal.goal_time_tolerance;
        Ok(NewGoal {
            info: GoalInfo { goal_id: r.goal_id, stamp },
            path,
            path_tolerance,
            goal_tolerance,
            goal_time: match Duration::new(d.sec.max(0) as u64, d.nanosec.min(999_999_999)) {
                Duration::ZERO => DEFAULT_GOAL_TIME,
                t => t,
            },
        })
    }

    /// Goal `goal` runs: the controller took its path as order `path`; the samples from cycle
    /// `from_cycle` on are the goal's.
    pub fn start(&mut self, goal: NewGoal, path: u64, from_cycle: u64) {
        let knots = goal.path.knots();
        let run = Run {
            path,
            stopping: None,
            from_cycle,
            end: Motion::at(knots[knots.len() - 1].pos),
            path_tolerance: goal.path_tolerance,
            goal_tolerance: goal.goal_tolerance,
            goal_time: goal.goal_time,
            ended_at: None,
        };
        if self.goals.len() >= KEPT_GOALS
            && let Some(i) = self.goals.iter().position(|g| ended(g.status))
        {
            self.goals.remove(i);
        }
        self.goals.push(Goal {
            info: goal.info,
            status: GoalStatus::EXECUTING,
            result: FjtResult::default(),
            run: Some(run),
        });
        self.changed = true;
    }

    /// A goal's tolerances in counts, if its joints are the robot's and it has no multi-DOF
    /// part.
    fn goal_bounds(&self, r: &SendGoalRequest) -> Result<(Tolerances, Tolerances), String> {
        let g = &r.goal;
        if !g.multi_dof_trajectory.joint_names.is_empty()
            || !g.multi_dof_trajectory.points.is_empty()
            || !g.component_path_tolerance.is_empty()
            || !g.component_goal_tolerance.is_empty()
        {
            return Err("the robot has no multi-DOF joints: leave them empty".into());
        }
        let per_rad = self.converter.counts_per_rad;
        let of = |list: &[JointTolerance], what: &str| -> Result<Tolerances, String> {
            let mut t = Tolerances::default();
            for j in list {
                let m = self
                    .converter
                    .motor_of(&j.name)
                    .ok_or_else(|| format!("{what}: no joint {:?}", j.name))?;
                if !(j.position.is_finite() && j.velocity.is_finite()) {
                    return Err(format!("{what}: {}: the numbers must be finite", j.name));
                }
                // (-1, "none", and 0, "the default", are both unchecked here.)
                t.position[m] = j.position.max(0.0) * per_rad;
                t.velocity[m] = j.velocity.max(0.0) * per_rad;
            }
            Ok(t)
        };
        Ok((of(&g.path_tolerance, "path_tolerance")?, of(&g.goal_tolerance, "goal_tolerance")?))
    }

    /// The answer to `get_result` for `goal_id` now: `None` while the goal runs (the client
    /// waits for its [`Finished`]).
    pub fn result(&self, goal_id: &Uuid) -> Option<GetResultResponse> {
        match self.goals.iter().find(|g| g.info.goal_id == *goal_id) {
            Some(g) if !ended(g.status) => None,
            Some(g) => Some(GetResultResponse { status: g.status, result: g.result.clone() }),
            None => Some(GetResultResponse { status: GoalStatus::UNKNOWN, ..Default::default() }),
        }
    }

    /// Cancels what `info` names: the answer, and the stop to send if a goal is to stop.
    pub fn cancel(&mut self, info: &GoalInfo) -> (CancelGoalResponse, Option<StopFor>) {
        let all = info.goal_id == Uuid::default();
        let known = self.goals.iter().any(|g| all || g.info.goal_id == info.goal_id);
        let target = self.goals.iter_mut().find(|g| {
            (all || g.info.goal_id == info.goal_id)
                && g.run.as_ref().is_some_and(|r| r.stopping.is_none())
        });
        let Some(g) = target else {
            let return_code = if known || all {
                CancelGoalResponse::ERROR_GOAL_TERMINATED
            } else {
                CancelGoalResponse::ERROR_UNKNOWN_GOAL_ID
            };
            return (CancelGoalResponse { return_code, goals_canceling: Vec::new() }, None);
        };
        // Canceling until the robot rests (at once canceled if the stop cannot be sent).
        g.status = GoalStatus::CANCELING;
        self.changed = true;
        let canceled =
            FjtResult { error_code: FjtResult::SUCCESSFUL, error_string: "canceled".into() };
        let answer = CancelGoalResponse {
            return_code: CancelGoalResponse::ERROR_NONE,
            goals_canceling: vec![g.info],
        };
        let stop =
            StopFor { goal_id: g.info.goal_id, status: GoalStatus::CANCELED, result: canceled };
        (answer, Some(stop))
    }

    /// The stop `stop` asked for was sent as order `sent`, or could not be (`None`: the
    /// session has ended), and the goal ends at once.
    pub fn stop_sent(&mut self, stop: StopFor, sent: Option<u64>) -> Option<Finished> {
        self.changed = true;
        let i = self.goals.iter().position(|g| g.info.goal_id == stop.goal_id)?;
        let StopFor { status, result, .. } = stop;
        match (sent, self.goals[i].run.as_mut()) {
            (Some(id), Some(run)) => {
                run.stopping = Some(Stopping { id, status, result });
                None
            }
            _ => Some(self.finish(i, status, result)),
        }
    }

    /// The controller does not answer (`why`): the running goal is aborted.
    pub fn lost(&mut self, why: String) -> Option<Finished> {
        let i = self.goals.iter().position(|g| g.run.is_some())?;
        Some(self.finish(i, GoalStatus::ABORTED, aborted(FjtResult::INVALID_GOAL, why)))
    }

    /// Ends goal `i`.
    fn finish(&mut self, i: usize, status: i8, result: FjtResult) -> Finished {
        let g = &mut self.goals[i];
        g.status = status;
        g.result = result;
        g.run = None;
        self.changed = true;
        Finished {
            goal_id: g.info.goal_id,
            response: GetResultResponse { status, result: g.result.clone() },
        }
    }

    /// The goals' status, when it changed since the last call (published on every change,
    /// as rcl_action does).
    pub fn status_changed(&mut self) -> Option<GoalStatusArray> {
        if !std::mem::take(&mut self.changed) {
            return None;
        }
        let list = self.goals.iter().map(|g| GoalStatus { goal_info: g.info, status: g.status });
        Some(GoalStatusArray { status_list: list.collect() })
    }

    /// The running goal against the robot — the loop's `status` and what the telemetry
    /// showed, at `now` (ROS time `stamp`): feedback, tolerances, its end.
    pub fn watch(
        &mut self,
        status: &CommandResponse,
        seen: &Seen<'_>,
        stamp: Time,
        now: Instant,
    ) -> Watched {
        let mut out = Watched::default();
        let Some(i) = self.goals.iter().position(|g| g.run.is_some()) else { return out };
        let n = self.converter.n_motors;
        let per_rad = self.converter.counts_per_rad;
        let Some(run) = self.goals[i].run.as_mut() else { return out };
        let ledger = OrderLedger::of(status);
        if let Some(stop) = &run.stopping {
            // At rest past the stop (whatever was sent after it), or the session over.
            if ledger.rests_past(stop.id) || ledger.ended.is_some() {
                let Some(Stopping { status, result, .. }) = run.stopping.take() else {
                    return out;
                };
                out.finished = Some(self.finish(i, status, result));
            }
            return out;
        }
        if let Some(outcome) = ended_by(ledger.fate(run.path)) {
            out.finished = Some(self.finish(i, GoalStatus::ABORTED, outcome));
            return out;
        }
        // The path's samples (once the loop took it: the telemetry before is the last move's):
        // the path tolerance in every sample received — positions, and velocities over the
        // velocity window before it (a velocity over one sample is too coarse) once all of it
        // is the goal's — and feedback.
        if seen.last.is_some() && status.orders.taken >= run.path {
            let (positions, velocities) = run.path_tolerance.split();
            let broken = seen.fresh.iter().filter(|(_, s)| s.cycle >= run.from_cycle).find_map(
                |(first, s)| {
                    beyond(&positions, &Motion::at(s.cmd), &Motion::at(s.act), n).or_else(|| {
                        let (desired, actual) = motions(first, s);
                        (first.cycle >= run.from_cycle)
                            .then(|| beyond(&velocities, &desired, &actual, n))
                            .flatten()
                    })
                },
            );
            let goal_id = self.goals[i].info.goal_id;
            if let Some(v) = broken {
                let why = format!("path tolerance violated: {} from its command", v.words(per_rad));
                let result = aborted(FjtResult::PATH_TOLERANCE_VIOLATED, why);
                out.stop = Some(StopFor { goal_id, status: GoalStatus::ABORTED, result });
                return out;
            }
            let due = self.feedback_at.is_none_or(|t| {
                now.saturating_duration_since(t).as_secs_f64() >= 1.0 / FEEDBACK_HZ
            });
            if due {
                self.feedback_at = Some(now);
                out.feedback = Some(feedback(&self.converter, seen.motions, goal_id, stamp));
            }
        }
        let Some(run) = self.goals[i].run.as_mut() else { return out };
        if ledger.fate(run.path) != Fate::Settled {
            return out;
        }
        // The telemetry shows the command at the end too (its last samples have been checked
        // against the path tolerance: they come later than the status, through a relay).
        let at_end = |s: &TelemetrySample| {
            s.cycle >= run.from_cycle
                && (0..n).all(|m| (s.cmd[m] - run.end.position[m]).abs() <= END_MATCH_COUNTS)
        };
        if !seen.last.is_none_or(at_end) {
            return out;
        }
        // At rest at the end: within the goal tolerance, in goal_time_tolerance.
        let ended_at = *run.ended_at.get_or_insert(now);
        let since = now.saturating_duration_since(ended_at);
        let at = Motion { position: status.robot.actual, velocity: seen.motions.1.velocity };
        out.finished = match beyond(&run.goal_tolerance, &run.end, &at, n) {
            None => {
                let done =
                    FjtResult { error_code: FjtResult::SUCCESSFUL, error_string: String::new() };
                Some(self.finish(i, GoalStatus::SUCCEEDED, done))
            }
            Some(v) if since > run.goal_time => {
                let why = format!(
                    "goal tolerance violated: {} from the goal {:.3} s after the path's end",
                    v.words(per_rad),
                    since.as_secs_f64(),
                );
                let result = aborted(FjtResult::GOAL_TOLERANCE_VIOLATED, why);
                Some(self.finish(i, GoalStatus::ABORTED, result))
            }
            Some(_) => None,
        };
        out
    }
}

/// The feedback of a sample's `(desired, actual)` motions: desired (the command), actual, and
/// their difference, rad and rad/s.
fn feedback(
    c: &Converter,
    motions: (Motion, Motion),
    goal_id: Uuid,
    stamp: Time,
) -> FeedbackMessage {
    let (desired, actual) = motions;
    let error = Motion {
        position: std::array::from_fn(|m| desired.position[m] - actual.position[m]),
        velocity: std::array::from_fn(|m| desired.velocity[m] - actual.velocity[m]),
    };
    let point = |m: &Motion| JointTrajectoryPoint {
        positions: c.rad(&m.position),
        velocities: c.rad(&m.velocity),
        ..JointTrajectoryPoint::default()
    };
    FeedbackMessage {
        goal_id,
        feedback: FjtFeedback {
            header: Header { stamp, frame_id: String::new() },
            joint_names: c.names(),
            desired: point(&desired),
            actual: point(&actual),
            error: point(&error),
            ..FjtFeedback::default()
        },
    }
}

/// The loop's command (desired) and the motors (actual) in sample `s`: positions, and
/// velocities since sample `first` (0 if it is no earlier).
pub fn motions(first: &TelemetrySample, s: &TelemetrySample) -> (Motion, Motion) {
    let dt = seconds_between(s, Some(first));
    let motion = |of: fn(&TelemetrySample) -> &[f64; MAX_MOTORS]| Motion {
        position: *of(s),
        velocity: rate(of(s), Some(of(first)), dt),
    };
    (motion(|s| &s.cmd), motion(|s| &s.act))
}

/// An aborted goal's result.
fn aborted(error_code: i32, error_string: String) -> FjtResult {
    FjtResult { error_code, error_string }
}

/// The goal's end if the path's `fate` ended it before it settled: the session ended, the
/// loop did not take the path, or another command took over the robot.
fn ended_by(fate: Fate) -> Option<FjtResult> {
    let why = match fate {
        Fate::Ended(fault) => {
            fault.map_or("the session ended".to_string(), |f| format!("fault: {f}"))
        }
        Fate::NotTaken => "the loop did not take the path".into(),
        Fate::Superseded(by) => format!("another command (move {by}) took over the robot"),
        Fate::Queued | Fate::Running | Fate::Settled => return None,
    };
    Some(aborted(FjtResult::INVALID_GOAL, why))
}

#[cfg(test)]
mod tests;
