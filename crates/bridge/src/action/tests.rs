//! The action's tolerance checks: which motor, which of its position or velocity, and the
//! boundary (exactly at the tolerance is within it).

use super::{Motion, Tolerances, Violation, beyond, ended};
use crate::action_msgs::{FjtResult, GoalStatus};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::state::FaultKind;
use qmarc_session::client::OrderLedger;
use qmarc_session::wire::{CommandResponse, Refusal};

fn motion(position: [f64; 3], velocity: [f64; 3]) -> Motion {
    let mut m = Motion::default();
    m.position[..3].copy_from_slice(&position);
    m.velocity[..3].copy_from_slice(&velocity);
    m
}

#[test]
fn a_motor_beyond_its_position_or_velocity_tolerance_is_named_the_boundary_within() {
    let want = motion([100.0, 200.0, 300.0], [1000.0, 0.0, -500.0]);
    let tol = motion([10.0, 10.0, 10.0], [50.0, 50.0, 50.0]);
    // Exactly at each tolerance: within.
    let edge = motion([110.0, 190.0, 310.0], [1050.0, -50.0, -450.0]);
    assert_eq!(beyond(&tol, &want, &edge, 3), None);
    // Motor 2's position a count further.
    let far = motion([110.0, 189.0, 300.0], [1000.0, 0.0, -500.0]);
    let v = Violation { motor: 1, what: "position", off: 11.0, tolerance: 10.0 };
    assert_eq!(beyond(&tol, &want, &far, 3), Some(v));
    // Motor 3's velocity 51 counts/s off, its position within.
    let fast = motion([100.0, 200.0, 300.0], [1000.0, 0.0, -449.0]);
    let v = Violation { motor: 2, what: "velocity", off: 51.0, tolerance: 50.0 };
    assert_eq!(beyond(&tol, &want, &fast, 3), Some(v));
    // The first motor beyond is named; of one motor, its position before its velocity.
    let both = motion([100.0, 250.0, 400.0], [1000.0, 100.0, 0.0]);
    assert_eq!(beyond(&tol, &want, &both, 3).unwrap().motor, 1);
    assert_eq!(beyond(&tol, &want, &both, 3).unwrap().what, "position");
    // Only the first n motors count.
    assert_eq!(beyond(&tol, &want, &both, 1), None);
}

#[test]
fn a_tolerance_of_zero_is_not_checked() {
    let want = motion([100.0, 200.0, 300.0], [0.0; 3]);
    let got = motion([-900.0, 200.0, 300.0], [0.0, 5000.0, 0.0]);
    assert_eq!(beyond(&Tolerances::default(), &want, &got, 3), None);
    let only_velocity = motion([0.0; 3], [0.0, 10.0, 0.0]);
    assert_eq!(
        beyond(&only_velocity, &want, &got, 3).map(|v| (v.motor, v.what)),
        Some((1, "velocity"))
    );
    let mut only_position = Tolerances::default();
    only_position.position[0] = 10.0;
    assert_eq!(beyond(&only_position, &want, &got, MAX_MOTORS).map(|v| v.off), Some(1000.0));
}

#[test]
fn a_violation_is_said_in_radians() {
    let v = Violation { motor: 2, what: "velocity", off: 200.0, tolerance: 100.0 };
    assert_eq!(v.words(1000.0), "motor3's velocity is 0.20000 rad/s off (tolerance 0.10000 rad/s)");
    let v = Violation { motor: 0, what: "position", off: 5.0, tolerance: 2.0 };
    assert_eq!(v.words(1000.0), "motor1's position is 0.00500 rad off (tolerance 0.00200 rad)");
}

/// What ends a running path other than its end: the session's end, a fault, the loop not
/// taking it, another motion; a grip (no motion) and the path itself do not.
#[test]
fn a_path_is_ended_by_a_fault_the_sessions_end_or_another_motion_only() {
    let ended_by = |s: &CommandResponse, path| super::ended_by(OrderLedger::of(s).fate(path));
    let path = 7;
    let mut running = CommandResponse::default();
    running.answer.ok = 1;
    (running.orders.accepted, running.orders.motion) = (path, path);
    let with = |change: &dyn Fn(&mut CommandResponse)| {
        let mut s = running;
        change(&mut s);
        s
    };
    assert_eq!(ended_by(&running, path), None);
    // The loop has not taken it yet: still its own.
    assert_eq!(ended_by(&with(&|s| s.orders.motion = path - 1), path), None);
    let gone = with(&|s| (s.answer.ok, s.answer.refusal) = (0, Refusal::NotServing as u32));
    let r = ended_by(&gone, path).unwrap();
    assert_eq!(
        (r.error_code, r.error_string.as_str()),
        (FjtResult::INVALID_GOAL, "the session ended")
    );
    // Any other refusal of the status is no end.
    let busy = with(&|s| (s.answer.ok, s.answer.refusal) = (0, Refusal::Busy as u32));
    assert_eq!(ended_by(&busy, path), None);
    let fault = with(&|s| s.robot.fault = FaultKind::wire(Some(FaultKind::FollowingError)));
    let r = ended_by(&fault, path).unwrap();
    assert!(r.error_string.starts_with("fault: following_error"), "{}", r.error_string);
    let dropped = with(&|s| s.orders.not_taken = path);
    assert_eq!(ended_by(&dropped, path).unwrap().error_string, "the loop did not take the path");
    assert_eq!(ended_by(&with(&|s| s.orders.not_taken = path - 1), path), None);
    let taken_over = with(&|s| s.orders.motion = path + 1);
    let r = ended_by(&taken_over, path).unwrap();
    assert_eq!(r.error_string, "another command (move 8) took over the robot");
}

#[test]
fn only_succeeded_canceled_and_aborted_goals_have_ended() {
    let all = [
        GoalStatus::UNKNOWN,
        1, // ACCEPTED
        GoalStatus::EXECUTING,
        GoalStatus::CANCELING,
        GoalStatus::SUCCEEDED,
        GoalStatus::CANCELED,
        GoalStatus::ABORTED,
    ];
    let over: Vec<i8> = all.into_iter().filter(|&s| ended(s)).collect();
    assert_eq!(over, [GoalStatus::SUCCEEDED, GoalStatus::CANCELED, GoalStatus::ABORTED]);
}

/// A tracker for three motors at 1000 counts a radian, and a goal to 0.1 rad on each in 1 s
/// (its id the byte `id`).
fn tracker_and_goal(id: u8) -> (super::GoalTracker, crate::action_msgs::SendGoalRequest) {
    use crate::msgs::{Duration, JointTrajectory, JointTrajectoryPoint};
    let converter = crate::convert::Converter { n_motors: 3, counts_per_rad: 1000.0, robot: None };
    let point = JointTrajectoryPoint {
        positions: vec![0.1; 3],
        time_from_start: Duration { sec: 1, nanosec: 0 },
        ..Default::default()
    };
    let mut r = crate::action_msgs::SendGoalRequest::default();
    r.goal_id.uuid[0] = id;
    r.goal.trajectory = JointTrajectory {
        joint_names: converter.names(),
        points: vec![point],
        ..Default::default()
    };
    (super::GoalTracker::new(converter), r)
}

/// The tracker alone, with no I/O: a goal runs once its path is taken; a second is refused
/// while it runs; a cancel asks for a stop, and the goal ends canceled only once the robot
/// rests past that stop — its result then answered, and the status published once a change.
#[test]
fn a_cancelled_goal_ends_canceled_once_the_robot_rests_past_its_stop() {
    use super::Seen;
    use crate::msgs::Time;
    let (mut t, r) = tracker_and_goal(1);
    let goal = t.check(&r, Time::default()).unwrap();
    assert_eq!(goal.path.knots().last().unwrap().pos[..3], [100.0; 3]);
    t.start(goal, 7, 0);
    assert!(t.running());
    assert!(t.status_changed().is_some());
    assert!(t.status_changed().is_none(), "published once a change");
    let (_, second) = tracker_and_goal(2);
    assert_eq!(
        t.check(&second, Time::default()).err().unwrap(),
        "a goal is running: cancel it first"
    );
    assert_eq!(t.result(&r.goal_id), None, "a running goal's result is waited for");
    let (answer, stop) =
        t.cancel(&crate::action_msgs::GoalInfo { goal_id: r.goal_id, ..Default::default() });
    assert_eq!(answer.goals_canceling.len(), 1);
    assert_eq!(t.stop_sent(stop.unwrap(), Some(9)), None, "canceling until the robot rests");
    let seen = Seen { fresh: &[], last: None, motions: Default::default() };
    let now = std::time::Instant::now();
    let mut moving = CommandResponse::default();
    (moving.answer.ok, moving.orders.settled, moving.orders.moving) = (1, 7, 1);
    assert!(t.watch(&moving, &seen, Time::default(), now).finished.is_none());
    let mut rests = CommandResponse::default();
    (rests.answer.ok, rests.orders.settled) = (1, 9);
    let done = t.watch(&rests, &seen, Time::default(), now).finished.unwrap();
    assert_eq!((done.goal_id, done.response.status), (r.goal_id, GoalStatus::CANCELED));
    assert_eq!(t.result(&r.goal_id).unwrap().status, GoalStatus::CANCELED);
    assert!(!t.running());
    // A stop that cannot be sent (the session ended) ends the goal at once.
    let goal = t.check(&second, Time::default()).unwrap();
    t.start(goal, 10, 0);
    let (_, stop) = t.cancel(&crate::action_msgs::GoalInfo::default());
    let done = t.stop_sent(stop.unwrap(), None).unwrap();
    assert_eq!(done.response.status, GoalStatus::CANCELED);
}
