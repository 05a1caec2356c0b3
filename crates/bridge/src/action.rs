//! `NS/qmarc/follow_joint_trajectory`: the `control_msgs/action/FollowJointTrajectory` server
//! MoveIt drives arms with, as rcl_action lays an action out on rmw_zenoh — three services
//! (`_action/send_goal`, `_action/cancel_goal`, `_action/get_result`) and two topics
//! (`_action/feedback`, `_action/status`).
//!
//! A goal is the path of its trajectory (`qmarc/path`, as `qmarc/joint_trajectory` sends it):
//! accepted when the controller takes the path, rejected with the reason logged and in
//! `/diagnostics` when it or the bridge refuses it, or while another goal runs. While it
//! runs, the feedback is the loop's command (desired), the motors (actual) and their
//! difference, from the telemetry; a joint further from its command than its path tolerance
//! stops the robot and aborts the goal (`PATH_TOLERANCE_VIOLATED`). Once the command rests at
//! the path's end, each joint has `goal_time_tolerance` to be within its goal tolerance
//! (`GOAL_TOLERANCE_VIOLATED` if not). The tolerances bound positions: 0 (or none given) is
//! not checked, and velocity and acceleration bounds never are. A cancel stops the robot (jerk-limited) and the goal ends
//! canceled once it rests; a fault, the session's end or another motion (a move, a stop — a
//! grip on the way is none) ends it aborted. A `goal_time_tolerance` of 0 is
//! [`DEFAULT_GOAL_TIME`].

use crate::action_msgs::{
    CancelGoalRequest, CancelGoalResponse, FeedbackMessage, FjtFeedback, FjtResult,
    GetResultRequest, GetResultResponse, GoalInfo, GoalStatus, GoalStatusArray, JointTolerance,
    SendGoalRequest, SendGoalResponse, Uuid,
};
use crate::bridge::{Bridge, publish, reply_with};
use crate::msgs::{Header, JointTrajectoryPoint, Time};
use crate::node::{Node, RosPublisher, RosService, ZenohError, payload_of};
use crate::ros2::{self, Qos};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::command::{CommandKind, CommandRequest, CommandResponse, Refusal};
use std::time::{Duration, Instant};

/// Ended goals the server still answers for (the oldest forgotten first).
const KEPT_GOALS: usize = 16;

/// How long after the path's end the joints have to be within the goal tolerance when the
/// goal leaves `goal_time_tolerance` 0 (the server's default, as the message's comment says).
pub const DEFAULT_GOAL_TIME: Duration = Duration::from_secs(1);

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

/// A running goal's position bounds, counts, per motor (0: unchecked).
type Tolerances = [f64; MAX_MOTORS];

/// The first motor (of `n`) further from `want` than its tolerance in `tol` (0: unchecked).
fn beyond(
    tol: &Tolerances,
    want: &[f64; MAX_MOTORS],
    got: &[f64; MAX_MOTORS],
    n: usize,
) -> Option<usize> {
    (0..n).find(|&m| tol[m] > 0.0 && (want[m] - got[m]).abs() > tol[m])
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
    /// The path's end, counts.
    end: [f64; MAX_MOTORS],
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
    status_at: Option<Instant>,
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
        let due = self.actions.status_at.is_none_or(|t| t.elapsed() >= Duration::from_secs(1));
        if self.actions.changed || (due && !self.actions.goals.is_empty()) {
            let list = self
                .actions
                .goals
                .iter()
                .map(|g| GoalStatus { goal_info: g.info, status: g.status })
                .collect();
            publish(&mut self.e.action.status, &GoalStatusArray { status_list: list });
            self.actions.status_at = Some(Instant::now());
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
            end: path.knots()[path.knots().len() - 1].pos,
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
            let mut t: Tolerances = [0.0; MAX_MOTORS];
            for j in list {
                let m = self
                    .opts
                    .converter
                    .motor_of(&j.name)
                    .ok_or_else(|| format!("{what}: no joint {:?}", j.name))?;
                if !j.position.is_finite() {
                    return Err(format!("{what}: {}: the position must be finite", j.name));
                }
                t[m] = j.position.max(0.0) * per_rad;
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
        let Some(run) = self.actions.goals[i].run.as_mut() else { return };
        if let Some(stop) = &run.stopping {
            let rested = status.settled >= stop.id && status.moving == 0;
            let gone = status.refused() == Some(Refusal::NotServing);
            if rested || gone {
                let Some(Stopping { status, result, .. }) = run.stopping.take() else { return };
                self.finish(i, status, result);
            }
            return;
        }
        if let Some(outcome) = ended_by(&status, run.path) {
            return self.finish(i, GoalStatus::ABORTED, outcome);
        }
        // The path's samples (once the loop took it: the telemetry before is the last move's):
        // feedback, and the path tolerance.
        if let (Some(s), true) = (self.last, status.taken >= run.path) {
            if let Some(m) = beyond(&run.path_tolerance, &s.cmd, &s.act, n) {
                let why = format!(
                    "path tolerance violated: motor{} is {:.5} rad from its command (tolerance \
                     {:.5} rad)",
                    m + 1,
                    (s.cmd[m] - s.act[m]).abs() / per_rad,
                    run.path_tolerance[m] / per_rad
                );
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
                let feedback = self.feedback(goal_id, &s, stamp);
                publish(&mut self.e.action.feedback, &feedback);
            }
        }
        let Some(run) = self.actions.goals[i].run.as_mut() else { return };
        if status.settled < run.path || status.moving != 0 {
            return;
        }
        // At rest at the end: within the goal tolerance, in goal_time_tolerance.
        let ended_at = *run.ended_at.get_or_insert_with(Instant::now);
        match beyond(&run.goal_tolerance, &run.end, &status.actual, n) {
            None => {
                let done =
                    FjtResult { error_code: FjtResult::SUCCESSFUL, error_string: String::new() };
                self.finish(i, GoalStatus::SUCCEEDED, done);
            }
            Some(m) if ended_at.elapsed() > run.goal_time => {
                let why = format!(
                    "goal tolerance violated: motor{} is {:.6} rad from the goal {:.3} s after \
                     the path's end (tolerance {:.6} rad)",
                    m + 1,
                    (status.actual[m] - run.end[m]).abs() / per_rad,
                    ended_at.elapsed().as_secs_f64(),
                    run.goal_tolerance[m] / per_rad
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

    /// The feedback of sample `s`: desired (the command), actual, and their difference, rad
    /// and rad/s.
    fn feedback(
        &self,
        goal_id: Uuid,
        s: &qmarc_proto::telemetry::TelemetrySample,
        stamp: Time,
    ) -> FeedbackMessage {
        let c = self.opts.converter;
        let n = c.n_motors;
        let velocity = |v: &[f64; MAX_MOTORS],
                        prev: Option<&[f64; MAX_MOTORS]>,
                        dt: f64|
         -> Vec<f64> {
            (0..n).map(|m| prev.map_or(0.0, |p| (v[m] - p[m]) / c.counts_per_rad / dt)).collect()
        };
        let prev = self.before_last.as_ref();
        let dt =
            prev.map_or(1.0, |p| (s.time_ns.saturating_sub(p.time_ns) as f64 * 1e-9).max(1e-9));
        let point =
            |pos: &[f64; MAX_MOTORS], prev_pos: Option<&[f64; MAX_MOTORS]>| JointTrajectoryPoint {
                positions: (0..n).map(|m| pos[m] / c.counts_per_rad).collect(),
                velocities: velocity(pos, prev_pos, dt),
                ..JointTrajectoryPoint::default()
            };
        let desired = point(&s.cmd, prev.map(|p| &p.cmd));
        let actual = point(&s.act, prev.map(|p| &p.act));
        let minus = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(a, b)| a - b).collect();
        let error = JointTrajectoryPoint {
            positions: minus(&desired.positions, &actual.positions),
            velocities: minus(&desired.velocities, &actual.velocities),
            ..JointTrajectoryPoint::default()
        };
        FeedbackMessage {
            goal_id,
            feedback: FjtFeedback {
                header: Header { stamp, frame_id: String::new() },
                joint_names: c.names(),
                desired,
                actual,
                error,
                ..FjtFeedback::default()
            },
        }
    }
}

/// An aborted goal's result.
fn aborted(error_code: i32, error_string: String) -> FjtResult {
    FjtResult { error_code, error_string }
}

/// What ended the path `path` other than its own end, if anything did: the session's end or
/// fault, the loop not taking it, or another motion (a move, a line, a stop; a grip is none).
fn ended_by(s: &CommandResponse, path: u64) -> Option<FjtResult> {
    if s.refused() == Some(Refusal::NotServing) || s.fault != 0 {
        let fault = qmarc_proto::state::FaultKind::from_wire(s.fault)
            .map_or("the session ended".to_string(), |f| format!("fault: {f}"));
        return Some(aborted(FjtResult::INVALID_GOAL, fault));
    }
    if s.not_taken >= path {
        return Some(aborted(FjtResult::INVALID_GOAL, "the loop did not take the path".into()));
    }
    if s.motion > path {
        let why = format!("another command (move {}) took over the robot", s.motion);
        return Some(aborted(FjtResult::INVALID_GOAL, why));
    }
    None
}
