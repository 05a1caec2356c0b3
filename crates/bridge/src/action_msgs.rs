//! The messages of `control_msgs/action/FollowJointTrajectory` (control_msgs 5.x, every Jazzy
//! release) and of `action_msgs`, field for field, for `cdr-encoding`'s serde: what an action
//! client (MoveIt, `ros2 action send_goal`) sends and reads on the action's three services and
//! two topics.

use crate::msgs::{Duration, Header, JointTrajectory, JointTrajectoryPoint, Time};
use serde::{Deserialize, Serialize};

/// `unique_identifier_msgs/msg/UUID`: a goal's id.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Uuid {
    /// Its 16 bytes.
    pub uuid: [u8; 16],
}

/// `control_msgs/msg/JointTolerance`: 0 leaves a bound unchecked here.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTolerance {
    /// The joint.
    pub name: String,
    /// rad.
    pub position: f64,
    /// rad/s (not checked by the bridge).
    pub velocity: f64,
    /// rad/s² (not checked by the bridge).
    pub acceleration: f64,
}

/// `control_msgs/msg/JointComponentTolerance` (multi-DOF joints: the bridge has none).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointComponentTolerance {
    /// The joint.
    pub joint_name: String,
    /// Which component.
    pub component: u16,
    /// Position.
    pub position: f64,
    /// Velocity.
    pub velocity: f64,
    /// Acceleration.
    pub acceleration: f64,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `geometry_msgs/msg/Transform`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear.
    pub linear: Vector3,
    /// Angular.
    pub angular: Vector3,
}

/// `trajectory_msgs/msg/MultiDOFJointTrajectoryPoint`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiDofPoint {
    /// Per joint.
    pub transforms: Vec<Transform>,
    /// Per joint.
    pub velocities: Vec<Twist>,
    /// Per joint.
    pub accelerations: Vec<Twist>,
    /// When.
    pub time_from_start: Duration,
}

/// `trajectory_msgs/msg/MultiDOFJointTrajectory`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiDofTrajectory {
    /// Stamp and frame.
    pub header: Header,
    /// The joints.
    pub joint_names: Vec<String>,
    /// The points.
    pub points: Vec<MultiDofPoint>,
}

/// `control_msgs/action/FollowJointTrajectory_Goal`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FjtGoal {
    /// The joints' path.
    pub trajectory: JointTrajectory,
    /// Multi-DOF joints' (must be empty here).
    pub multi_dof_trajectory: MultiDofTrajectory,
    /// How far from its command each joint may be while it moves.
    pub path_tolerance: Vec<JointTolerance>,
    /// Multi-DOF (must be empty here).
    pub component_path_tolerance: Vec<JointComponentTolerance>,
    /// How far from the end each joint may be once the path ends.
    pub goal_tolerance: Vec<JointTolerance>,
    /// Multi-DOF (must be empty here).
    pub component_goal_tolerance: Vec<JointComponentTolerance>,
    /// How long after the path's end the joints have to be within the goal tolerance.
    pub goal_time_tolerance: Duration,
}

/// `…_SendGoal`'s request.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SendGoalRequest {
    /// The client's id for the goal.
    pub goal_id: Uuid,
    /// The goal.
    pub goal: FjtGoal,
}

/// `…_SendGoal`'s response.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SendGoalResponse {
    /// Taken.
    pub accepted: bool,
    /// When.
    pub stamp: Time,
}

/// `…_GetResult`'s request.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetResultRequest {
    /// Which goal.
    pub goal_id: Uuid,
}

/// `control_msgs/action/FollowJointTrajectory_Result`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FjtResult {
    /// [`FjtResult::SUCCESSFUL`] or what went wrong.
    pub error_code: i32,
    /// In words.
    pub error_string: String,
}

impl FjtResult {
    /// Done.
    pub const SUCCESSFUL: i32 = 0;
    /// Not a goal this robot can take.
    pub const INVALID_GOAL: i32 = -1;
    /// A joint moved further from its command than the path tolerance.
    pub const PATH_TOLERANCE_VIOLATED: i32 = -4;
    /// A joint was not within the goal tolerance in time.
    pub const GOAL_TOLERANCE_VIOLATED: i32 = -5;
}

/// `…_GetResult`'s response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetResultResponse {
    /// The goal's [`GoalStatus`] status.
    pub status: i8,
    /// The result.
    pub result: FjtResult,
}

/// `control_msgs/action/FollowJointTrajectory_Feedback`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FjtFeedback {
    /// Stamp.
    pub header: Header,
    /// The joints.
    pub joint_names: Vec<String>,
    /// The command.
    pub desired: JointTrajectoryPoint,
    /// Where the joints are.
    pub actual: JointTrajectoryPoint,
    /// desired − actual.
    pub error: JointTrajectoryPoint,
    /// None here.
    pub multi_dof_joint_names: Vec<String>,
    /// None here.
    pub multi_dof_desired: MultiDofPoint,
    /// None here.
    pub multi_dof_actual: MultiDofPoint,
    /// None here.
    pub multi_dof_error: MultiDofPoint,
}

/// `…_FeedbackMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FeedbackMessage {
    /// Which goal.
    pub goal_id: Uuid,
    /// Its feedback.
    pub feedback: FjtFeedback,
}

/// `action_msgs/msg/GoalInfo`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GoalInfo {
    /// The goal.
    pub goal_id: Uuid,
    /// When it was accepted (in a cancel request: cancel those accepted at or before).
    pub stamp: Time,
}

/// `action_msgs/msg/GoalStatus`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GoalStatus {
    /// The goal.
    pub goal_info: GoalInfo,
    /// One of the constants.
    pub status: i8,
}

impl GoalStatus {
    /// Unknown goal.
    pub const UNKNOWN: i8 = 0;
    /// Executing.
    pub const EXECUTING: i8 = 2;
    /// Being canceled.
    pub const CANCELING: i8 = 3;
    /// Done.
    pub const SUCCEEDED: i8 = 4;
    /// Canceled.
    pub const CANCELED: i8 = 5;
    /// Ended by the server.
    pub const ABORTED: i8 = 6;
}

/// `action_msgs/msg/GoalStatusArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GoalStatusArray {
    /// Every goal the server knows.
    pub status_list: Vec<GoalStatus>,
}

/// `action_msgs/srv/CancelGoal`'s request.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CancelGoalRequest {
    /// Which goals (a zero id: all; with a stamp, those accepted at or before it).
    pub goal_info: GoalInfo,
}

/// `action_msgs/srv/CancelGoal`'s response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CancelGoalResponse {
    /// 0 none, 1 rejected, 2 unknown goal, 3 goal already ended.
    pub return_code: i8,
    /// The goals now canceling.
    pub goals_canceling: Vec<GoalInfo>,
}

impl CancelGoalResponse {
    /// Canceling.
    pub const ERROR_NONE: i8 = 0;
    /// No such goal.
    pub const ERROR_UNKNOWN_GOAL_ID: i8 = 2;
    /// The goal has ended.
    pub const ERROR_GOAL_TERMINATED: i8 = 3;
}
