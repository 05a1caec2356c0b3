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

use crate::action_msgs::{
    CancelGoalRequest, CancelGoalResponse, FeedbackMessage, FjtFeedback, FjtResult,
    GetResultRequest, GetResultResponse, GoalInfo, GoalStatus, GoalStatusArray, JointTolerance,
    SendGoalRequest, SendGoalResponse, Uuid,
};
use crate::bridge::{Bridge, publish, reply_with};
use crate::convert::{rate, seconds_between};
use crate::msgs::{Header, JointTrajectoryPoint, Time};
use crate::node::{Node, RosPublisher, RosService, ZenohError, payload_of};
use crate::ros2::{self, Qos};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_session::client::{Fate, OrderLedger};
use qmarc_session::wire::{CommandKind, CommandRequest};
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

/// The action's entities.
pub struct ActionEntities {
    send_goal: RosService,
    cancel_goal: RosService,
    get_result: RosService,
    feedback: RosPublisher,
    status: RosPublisher,
}

impl ActionEntities {
    /// Declares the action `name` of `node`.
    pub fn declare(node: &mut Node, name: &str) -> Result<ActionEntities, ZenohError> {
        let at = |part: &str| format!("{name}/_action/{part}");
        Ok(ActionEntities {
            send_goal: node.service(&at("send_goal"), &ros2::FJT_SEND_GOAL)?,
            cancel_goal: node.service(&at("cancel_goal"), &ros2::CANCEL_GOAL)?,
            get_result: node.service(&at("get_result"), &ros2::FJT_GET_RESULT)?,
            feedback: node.publisher(&at("feedback"), &ros2::FJT_FEEDBACK, &Qos::DEFAULT)?,
            status: node.publisher(&at("status"), &ros2::GOAL_STATUS_ARRAY, &Qos::ACTION_STATUS)?,
        })
    }
}

/// Where each motor is and how fast it goes: counts and counts/s.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Motion {
    position: [f64; MAX_MOTORS],
    velocity: [f64; MAX_MOTORS],
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
    waiting: Vec<zenoh::query::Query>,
}

/// The action server's state.
#[derive(Default)]
pub struct Actions {
    goals: Vec<Goal>,
    feedback_at: Option<Instant>,
    changed: bool,
}

impl Actions {
    fn running(&mut self) -> Option<&mut Goal> {
        self.goals.iter_mut().find(|g| g.run.is_some())
    }
}

fn ended(status: i8) -> bool {
    matches!(status, GoalStatus::SUCCEEDED | GoalStatus::CANCELED | GoalStatus::ABORTED)
}

impl Bridge {
    /// The action's turn: requests answered, the running goal watched.
    pub(crate) fn actions(&mut self, stamp: Time) {
        while let Some(q) = self.e.action.send_goal.try_recv() {
            let reply = match ros2::from_cdr::<SendGoalRequest>(
                &payload_of(q.payload()),
                "FollowJointTrajectory_SendGoal",
            ) {
                Err(e) => {
                    self.bad_input("follow_joint_trajectory", &e.to_string());
                    SendGoalResponse { accepted: false, stamp }
                }
                Ok(r) => SendGoalResponse { accepted: self.send_goal(&r, stamp), stamp },
            };
            reply_with(&self.e.action.send_goal, &q, &reply);
        }
        while let Some(q) = self.e.action.cancel_goal.try_recv() {
            let reply =
                match ros2::from_cdr::<CancelGoalRequest>(&payload_of(q.payload()), "CancelGoal") {
                    Err(e) => {
                        self.bad_input("follow_joint_trajectory", &e.to_string());
                        CancelGoalResponse { return_code: 1, goals_canceling: Vec::new() }
                    }
                    Ok(r) => self.cancel(&r.goal_info),
                };
            reply_with(&self.e.action.cancel_goal, &q, &reply);
        }
        while let Some(q) = self.e.action.get_result.try_recv() {
            match ros2::from_cdr::<GetResultRequest>(&payload_of(q.payload()), "GetResult") {
                Err(e) => self.bad_input("follow_joint_trajectory", &e.to_string()),
                Ok(r) => {
                    match self.actions.goals.iter_mut().find(|g| g.info.goal_id == r.goal_id) {
                        Some(g) if !ended(g.status) => g.waiting.push(q),
                        Some(g) => {
                            let reply =
                                GetResultResponse { status: g.status, result: g.result.clone() };
                            reply_with(&self.e.action.get_result, &q, &reply);
                        }
                        None => reply_with(
                            &self.e.action.get_result,
                            &q,
                            &GetResultResponse {
                                status: GoalStatus::UNKNOWN,
                                ..Default::default()
                            },
                        ),
                    }
                }
            }
        }
        self.watch(stamp);
        // On every change, as rcl_action does: a client that joins later has the last from
        // the publisher's cache (transient local).
        if self.actions.changed {
            let list = self
                .actions
                .goals
                .iter()
                .map(|g| GoalStatus { goal_info: g.info, status: g.status })
                .collect();
            publish(&mut self.e.action.status, &GoalStatusArray { status_list: list });
            self.actions.changed = false;
        }
    }

    /// A new goal: true if the robot took it.
    fn send_goal(&mut self, r: &SendGoalRequest, stamp: Time) -> bool {
        let checked = if self.actions.running().is_some() {
            Err("a goal is running: cancel it first".to_string())
        } else if self.actions.goals.iter().any(|g| g.info.goal_id == r.goal_id) {
            Err("a goal with this id exists".to_string())
        } else {
            self.goal_bounds(r)
                .and_then(|t| self.opts.converter.path(&r.goal.trajectory).map(|p| (t, p)))
        };
        let ((path_tolerance, goal_tolerance), path) = match checked {
            Ok(c) => c,
            Err(why) => {
                self.bad_input("follow_joint_trajectory", &why);
                return false;
            }
        };
        let Ok(answer) = self.send_path(&path, "follow_joint_trajectory") else { return false };
        let d = r.goal.goal_time_tolerance;
        let run = Run {
            path: answer.accepted,
            stopping: None,
            from_cycle: self.last.map_or(0, |s| s.cycle + 1),
            end: Motion::at(path.knots()[path.knots().len() - 1].pos),
            path_tolerance,
            goal_tolerance,
            goal_time: match Duration::new(d.sec.max(0) as u64, d.nanosec.min(999_999_999)) {
                Duration::ZERO => DEFAULT_GOAL_TIME,
                t => t,
            },
            ended_at: None,
        };
        if self.actions.goals.len() >= KEPT_GOALS
            && let Some(i) = self.actions.goals.iter().position(|g| ended(g.status))
        {
            self.actions.goals.remove(i);
        }
        self.actions.goals.push(Goal {
            info: GoalInfo { goal_id: r.goal_id, stamp },
            status: GoalStatus::EXECUTING,
            result: FjtResult::default(),
            run: Some(run),
            waiting: Vec::new(),
        });
        self.actions.changed = true;
        true
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
        let per_rad = self.opts.converter.counts_per_rad;
        let of = |list: &[JointTolerance], what: &str| -> Result<Tolerances, String> {
            let mut t = Tolerances::default();
            for j in list {
                let m = self
                    .opts
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

    /// Cancels what `info` names.
    fn cancel(&mut self, info: &GoalInfo) -> CancelGoalResponse {
        let all = info.goal_id == Uuid::default();
        let known = self.actions.goals.iter().any(|g| all || g.info.goal_id == info.goal_id);
        let target = self.actions.goals.iter().position(|g| {
            (all || g.info.goal_id == info.goal_id)
                && g.run.as_ref().is_some_and(|r| r.stopping.is_none())
        });
        let Some(i) = target else {
            let return_code = if known || all {
                CancelGoalResponse::ERROR_GOAL_TERMINATED
            } else {
                CancelGoalResponse::ERROR_UNKNOWN_GOAL_ID
            };
            return CancelGoalResponse { return_code, goals_canceling: Vec::new() };
        };
        let canceled =
            FjtResult { error_code: FjtResult::SUCCESSFUL, error_string: "canceled".into() };
        // Canceling until the robot rests (at once canceled if the stop cannot be sent).
        self.actions.goals[i].status = GoalStatus::CANCELING;
        self.stop_goal(i, GoalStatus::CANCELED, canceled);
        CancelGoalResponse {
            return_code: CancelGoalResponse::ERROR_NONE,
            goals_canceling: vec![self.actions.goals[i].info],
        }
    }

    /// Stops the robot for goal `i`, which ends with `status` and `result` once it rests (at
    /// once if the stop is refused: the session has ended).
    fn stop_goal(&mut self, i: usize, status: i8, result: FjtResult) {
        let stop = self.command(CommandRequest::of(CommandKind::Stop), "follow_joint_trajectory");
        match stop {
            Ok(answer) => {
                if let Some(run) = self.actions.goals[i].run.as_mut() {
                    run.stopping = Some(Stopping { id: answer.accepted, status, result });
                }
            }
            Err(_) => self.finish(i, status, result),
        }
        self.actions.changed = true;
    }

    /// Ends goal `i`: its result to every client waiting for it.
    fn finish(&mut self, i: usize, status: i8, result: FjtResult) {
        let g = &mut self.actions.goals[i];
        g.status = status;
        g.result = result;
        g.run = None;
        if g.result.error_code != FjtResult::SUCCESSFUL {
            eprintln!("qmarc-bridge: follow_joint_trajectory: {}", g.result.error_string);
        }
        let reply = GetResultResponse { status, result: g.result.clone() };
        for q in std::mem::take(&mut g.waiting) {
            reply_with(&self.e.action.get_result, &q, &reply);
        }
        self.actions.changed = true;
    }

    /// The running goal against the robot: feedback, tolerances, its end.
    fn watch(&mut self, stamp: Time) {
        let Some(i) = self.actions.goals.iter().position(|g| g.run.is_some()) else { return };
        let status = match self.client.send(CommandRequest::of(CommandKind::Status)) {
            Ok(s) => s,
            Err(e) => {
                let why = format!("the controller does not answer: {e}");
                return self.finish(i, GoalStatus::ABORTED, aborted(FjtResult::INVALID_GOAL, why));
            }
        };
        let n = self.opts.converter.n_motors;
        let per_rad = self.opts.converter.counts_per_rad;
        let (_, actual) = self.motions();
        let Some(run) = self.actions.goals[i].run.as_mut() else { return };
        let ledger = OrderLedger::of(&status);
        if let Some(stop) = &run.stopping {
            // At rest past the stop (whatever was sent after it), or the session over.
            if ledger.rests_past(stop.id) || ledger.ended.is_some() {
                let Some(Stopping { status, result, .. }) = run.stopping.take() else { return };
                self.finish(i, status, result);
            }
            return;
        }
        if let Some(outcome) = ended_by(ledger.fate(run.path)) {
            return self.finish(i, GoalStatus::ABORTED, outcome);
        }
        // The path's samples (once the loop took it: the telemetry before is the last move's):
        // the path tolerance in every sample received — positions, and velocities over the
        // VELOCITY_WINDOW_NS before it (a velocity over one sample is too coarse) once all of
        // it is the goal's — and feedback.
        if self.last.is_some() && status.taken >= run.path {
            let (positions, velocities) = run.path_tolerance.split();
            let broken = self.fresh.iter().filter(|(_, s)| s.cycle >= run.from_cycle).find_map(
                |(first, s)| {
                    beyond(&positions, &Motion::at(s.cmd), &Motion::at(s.act), n).or_else(|| {
                        let (desired, actual) = motions(first, s);
                        (first.cycle >= run.from_cycle)
                            .then(|| beyond(&velocities, &desired, &actual, n))
                            .flatten()
                    })
                },
            );
            if let Some(v) = broken {
                let why = format!("path tolerance violated: {} from its command", v.words(per_rad));
                let result = aborted(FjtResult::PATH_TOLERANCE_VIOLATED, why);
                return self.stop_goal(i, GoalStatus::ABORTED, result);
            }
            let due = self
                .actions
                .feedback_at
                .is_none_or(|t| t.elapsed().as_secs_f64() >= 1.0 / FEEDBACK_HZ);
            if due {
                self.actions.feedback_at = Some(Instant::now());
                let goal_id = self.actions.goals[i].info.goal_id;
                let feedback = self.feedback(goal_id, stamp);
                publish(&mut self.e.action.feedback, &feedback);
            }
        }
        let Some(run) = self.actions.goals[i].run.as_mut() else { return };
        if ledger.fate(run.path) != Fate::Settled {
            return;
        }
        // The telemetry shows the command at the end too (its last samples have been checked
        // against the path tolerance: they come later than the status, through a relay).
        let at_end = |s: &TelemetrySample| {
            s.cycle >= run.from_cycle
                && (0..n).all(|m| (s.cmd[m] - run.end.position[m]).abs() <= END_MATCH_COUNTS)
        };
        if !self.last.as_ref().is_none_or(at_end) {
            return;
        }
        // At rest at the end: within the goal tolerance, in goal_time_tolerance.
        let ended_at = *run.ended_at.get_or_insert_with(Instant::now);
        let at = Motion { position: status.actual, velocity: actual.velocity };
        match beyond(&run.goal_tolerance, &run.end, &at, n) {
            None => {
                let done =
                    FjtResult { error_code: FjtResult::SUCCESSFUL, error_string: String::new() };
                self.finish(i, GoalStatus::SUCCEEDED, done);
            }
            Some(v) if ended_at.elapsed() > run.goal_time => {
                let why = format!(
                    "goal tolerance violated: {} from the goal {:.3} s after the path's end",
                    v.words(per_rad),
                    ended_at.elapsed().as_secs_f64(),
                );
                self.finish(
                    i,
                    GoalStatus::ABORTED,
                    aborted(FjtResult::GOAL_TOLERANCE_VIOLATED, why),
                );
            }
            Some(_) => {}
        }
    }

    /// The loop's command (desired) and the motors (actual) in its newest telemetry sample:
    /// positions, and velocities over the last [`crate::bridge::VELOCITY_WINDOW_NS`] (0
    /// without two samples).
    fn motions(&self) -> (Motion, Motion) {
        match (self.recent.front(), self.recent.back()) {
            (Some(first), Some(s)) => motions(first, s),
            _ => Default::default(),
        }
    }

    /// The feedback of the newest sample: desired (the command), actual, and their
    /// difference, rad and rad/s.
    fn feedback(&self, goal_id: Uuid, stamp: Time) -> FeedbackMessage {
        let c = self.opts.converter;
        let (desired, actual) = self.motions();
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
}

/// The loop's command (desired) and the motors (actual) in sample `s`: positions, and
/// velocities since sample `first` (0 if it is no earlier).
fn motions(first: &TelemetrySample, s: &TelemetrySample) -> (Motion, Motion) {
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
