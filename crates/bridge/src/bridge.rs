//! The bridge's loop: the robot's telemetry out as ROS 2 topics, ROS 2 targets and service
//! calls in as the serve mode's commands — one thread, the iceoryx2 ends (which are not
//! `Send`) and the Zenoh queues polled in turn, `--rate` times a second.
//!
//! Nothing from the network reaches the controller unchecked: a payload is bounded and fully
//! decoded, its numbers finite and near; the controller checks the rest (reach, soft limits,
//! homing) and refuses with a reason, which the bridge logs and puts in `/diagnostics`.

use crate::action::{Finished, GoalTracker, Seen, StopFor, motions};
use crate::action_msgs::{
    CancelGoalRequest, CancelGoalResponse, FjtResult, GetResultRequest, SendGoalRequest,
    SendGoalResponse, Uuid,
};
use crate::convert::{Converter, SessionState, target_mm};
use crate::msgs::{
    JointTrajectory, PointStamped, SetBoolRequest, SuccessResponse, Time, TriggerRequest,
};
use crate::node::{Node, RosPublisher, RosService, ZenohError, payload_of, session_config};
use crate::ros2::{self, Qos};
use qmarc_proto::progress::Progress;
use qmarc_proto::service::IpcLocation;
use qmarc_proto::telemetry::{TELEMETRY_BUFFER, TelemetrySample};
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest, CommandResponse, PathRequest};
use qmarc_telemetry::reader::{End, TelemetryReader};
use qmarc_timer::clock::monotonic_now_ns;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Farthest a target may be from the base, m (the serve mode refuses what the robot cannot
/// reach; this only keeps absurd numbers off the wire to it).
pub const TARGET_LIMIT_M: f64 = 10.0;

/// What the bridge serves.
#[derive(Debug, Clone)]
pub struct Options {
    /// The serving session's iceoryx2 files.
    pub location: IpcLocation,
    /// ROS namespace (`""` or `/robot1`).
    pub namespace: String,
    /// ROS domain id.
    pub domain: u32,
    /// Joint states a second.
    pub rate_hz: f64,
    /// A Zenoh configuration file instead of rmw_zenoh's defaults.
    pub zenoh_config: Option<PathBuf>,
    /// The robot, from the session's settings.
    pub converter: Converter,
    /// The hardware the diagnostics name (`sim`, `s626`).
    pub hardware_id: String,
}

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

/// A subscription's queue.
type Subscription =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// The node's entities.
struct Entities {
    joint_states: RosPublisher,
    effector: RosPublisher,
    diagnostics: RosPublisher,
    target: Subscription,
    trajectory: Subscription,
    stop: RosService,
    gripper: RosService,
    action: ActionEntities,
}

impl Entities {
    fn declare(node: &mut Node) -> Result<Entities, ZenohError> {
        Ok(Entities {
            joint_states: node.publisher("joint_states", &ros2::JOINT_STATE, &Qos::DEFAULT)?,
            effector: node.publisher("qmarc/effector", &ros2::POINT_STAMPED, &Qos::DEFAULT)?,
            diagnostics: node.publisher("/diagnostics", &ros2::DIAGNOSTIC_ARRAY, &Qos::DEFAULT)?,
            target: node.subscription("qmarc/target", &ros2::POINT_STAMPED, &Qos::DEFAULT)?,
            trajectory: node.subscription(
                "qmarc/joint_trajectory",
                &ros2::JOINT_TRAJECTORY,
                &Qos::DEFAULT,
            )?,
            stop: node.service("qmarc/stop", &ros2::TRIGGER)?,
            gripper: node.service("qmarc/gripper", &ros2::SET_BOOL)?,
            action: ActionEntities::declare(node, "qmarc/follow_joint_trajectory")?,
        })
    }
}

/// The bridge's state between turns.
struct Bridge {
    opts: Options,
    e: Entities,
    client: CommandClient,
    reader: TelemetryReader,
    /// The session's progress page: when its tick 0 was (none: stamps are the bridge's).
    progress: Option<Progress>,
    /// The newest sample.
    last: Option<TelemetrySample>,
    /// The sample of the last joint state published (its velocity is measured from it).
    published: Option<TelemetrySample>,
    /// The sample time the next joint state is due at, ns.
    next_joint_state_ns: Option<u64>,
    /// The samples of the last [`VELOCITY_WINDOW_NS`] and the newest one before: the
    /// action's velocities are measured from the first to the last.
    recent: VecDeque<TelemetrySample>,
    /// Every sample this turn received, oldest first, each with the first of its
    /// [`VELOCITY_WINDOW_NS`] (a running goal's path tolerance holds in each, however late
    /// the bridge turned).
    fresh: Vec<(TelemetrySample, TelemetrySample)>,
    /// The `FollowJointTrajectory` goals.
    goals: GoalTracker,
    /// The `get_result` calls waiting for their goal's end.
    waiting: Vec<(Uuid, zenoh::query::Query)>,
    homed: bool,
    /// A conveyor session's parts, by its last status: queued, picked, missed.
    parts: Option<[u32; 3]>,
    refused: String,
    said: Option<SessionState>,
    said_at: Option<Instant>,
    status_at: Option<Instant>,
}

/// The shortest time a velocity the action checks is measured over: one encoder count in it
/// is 50 counts/s (at 4 ms, a velocity would be 250 counts/s coarse).
const VELOCITY_WINDOW_NS: u64 = 20_000_000;

/// Serves until the session ends (`Ok`) or `stop` is set.
pub fn run(opts: Options, stop: &AtomicBool) -> anyhow::Result<()> {
    let mut node = Node::open(
        session_config(opts.zenoh_config.as_deref())?,
        opts.domain,
        &opts.namespace,
        "qmarc",
    )?;
    let e = Entities::declare(&mut node)?;
    let Some((client, reader)) = attach(&opts.location, stop)? else { return Ok(()) };
    eprintln!(
        "qmarc-bridge: serving {} as ROS 2 node {}qmarc, domain {}",
        opts.location.prefix,
        if node.namespace() == "/" { "/".to_string() } else { format!("{}/", node.namespace()) },
        opts.domain
    );
    let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
    let progress = Progress::open(&Progress::path(&opts.location.prefix)).ok();
    let goals = GoalTracker::new(opts.converter);
    let mut b = Bridge {
        opts,
        e,
        client,
        reader,
        progress,
        last: None,
        published: None,
        next_joint_state_ns: None,
        recent: VecDeque::with_capacity(TELEMETRY_BUFFER),
        fresh: Vec::with_capacity(TELEMETRY_BUFFER),
        goals,
        waiting: Vec::new(),
        homed: false,
        parts: None,
        refused: String::new(),
        said: None,
        said_at: None,
        status_at: None,
    };
    let mut next = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if b.turn()? {
            return Ok(());
        }
        // Paced by an absolute clock: a late turn is followed by the next one on time, not a
        // period after it (only a stall of many periods starts the schedule again).
        next += period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > 10 * period {
            next = now;
        }
    }
    Ok(())
}

/// How long a session that is starting may take to serve.
const ATTACH_WAIT: Duration = Duration::from_secs(30);

/// The session's command client and telemetry reader, once it serves (it may be starting:
/// `serve --bridge` starts the bridge with it); `None` if a stop signal came first.
fn attach(
    location: &IpcLocation,
    stop: &AtomicBool,
) -> anyhow::Result<Option<(CommandClient, TelemetryReader)>> {
    let since = Instant::now();
    loop {
        let client = CommandClient::connect(location).map_err(anyhow::Error::from);
        let reader = TelemetryReader::open_run(location)
            .map_err(|e| anyhow::anyhow!("the session's telemetry: {e:?}"));
        match (client, reader) {
            (Ok(c), Ok(r)) => return Ok(Some((c, r))),
            (Err(e), _) | (_, Err(e)) if since.elapsed() > ATTACH_WAIT => return Err(e),
            _ if stop.load(Ordering::Relaxed) => return Ok(None),
            _ => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

impl Bridge {
    /// One turn: telemetry out, commands in, diagnostics when due. True once the session
    /// has ended.
    fn turn(&mut self) -> anyhow::Result<bool> {
        self.fresh.clear();
        while let Some(s) = self.reader.receive().map_err(|e| anyhow::anyhow!(e))? {
            self.recent.push_back(s);
            while self.recent.len() > TELEMETRY_BUFFER
                || (self.recent.len() > 2
                    && s.time_ns.saturating_sub(self.recent[1].time_ns) >= VELOCITY_WINDOW_NS)
            {
                self.recent.pop_front();
            }
            self.fresh.push((self.recent[0], s));
        }
        let stamp = Time::now();
        // Joint states on a grid of the samples' own time, `--rate` a second of it: the
        // first sample at or after each grid point, however the samples arrive in batches
        // and however late a turn comes (issue 42: one a turn with fresh samples gave 196 Hz
        // of 250).
        for k in 0..self.fresh.len() {
            let s = self.fresh[k].1;
            if self.joint_state_due(&s) {
                let c = self.opts.converter;
                let taken = self.sample_time(&s).unwrap_or(stamp);
                let js = c.joint_state(&s, self.published.as_ref(), taken);
                self.published = Some(s);
                publish(&mut self.e.joint_states, &js);
                if let Some(p) = c.effector(&s, taken) {
                    publish(&mut self.e.effector, &p);
                }
            }
        }
        if let Some(&(_, s)) = self.fresh.last() {
            self.last = Some(s);
        }
        self.commands();
        self.actions(stamp);
        let ended = self.reader.end();
        self.diagnose(stamp, ended.as_ref());
        Ok(ended.is_some())
    }

    /// Whether sample `s` is the next joint state's: the first at or after the grid point
    /// due. After a gap of more than a period (samples lost, the session paused) the grid
    /// starts again from `s`.
    fn joint_state_due(&mut self, s: &TelemetrySample) -> bool {
        let period_ns = (1e9 / self.opts.rate_hz) as u64;
        let next = match self.next_joint_state_ns {
            // A sample from before the grid's last point but one: time went back (another
            // session's clock): the grid starts again from it.
            Some(due) if s.time_ns.saturating_add(2 * period_ns) < due => s.time_ns + period_ns,
            Some(due) if s.time_ns < due => return false,
            Some(due) if s.time_ns < due + period_ns => due + period_ns,
            _ => s.time_ns + period_ns,
        };
        self.next_joint_state_ns = Some(next);
        true
    }

    /// When the loop took sample `s`, on the system clock (ROS time): its tick's time from the
    /// session's tick 0 — if the session runs in real time, which a sample less than a second
    /// old says (a lock-step session's time is simulated).
    fn sample_time(&self, s: &TelemetrySample) -> Option<Time> {
        let t0 = self.progress.as_ref()?.read().t0_ns;
        let age = monotonic_now_ns().checked_sub(t0.checked_add(s.time_ns)?)?;
        let now_ns = u64::try_from(crate::node::now_ns()).ok()?;
        (t0 != 0 && age < 1_000_000_000).then(|| Time::from_ns(now_ns - age))
    }

    /// A command to the controller; its refusal, if refused, logged and kept for the
    /// diagnostics.
    fn command(&mut self, r: CommandRequest, what: &str) -> Result<CommandResponse, String> {
        let answer = self.client.send(r).map_err(|e| format!("{what}: {e}"));
        self.answered(answer, what)
    }

    /// The controller's answer to `what`: its refusal, if refused, logged and kept.
    fn answered(
        &mut self,
        answer: Result<CommandResponse, String>,
        what: &str,
    ) -> Result<CommandResponse, String> {
        let answer = answer.inspect_err(|why| {
            eprintln!("qmarc-bridge: not sent: {why}");
        })?;
        match answer.refused() {
            None => {
                self.refused.clear();
                Ok(answer)
            }
            Some(refusal) => {
                let why = format!("{what}: {} ({})", answer.reason(), refusal.name());
                eprintln!("qmarc-bridge: refused: {why}");
                self.refused = why.clone();
                Err(why)
            }
        }
    }

    /// A path to the controller; refused, logged and kept for the diagnostics.
    fn send_path(&mut self, path: &PathRequest, what: &str) -> Result<CommandResponse, String> {
        let answer = self.client.send_path(path).map_err(|e| format!("{what}: {e}"));
        self.answered(answer, what)
    }

    /// The targets and service calls that arrived.
    fn commands(&mut self) {
        while let Ok(Some(sample)) = self.e.target.try_recv() {
            let bytes = payload_of(Some(sample.payload()));
            let target = ros2::from_cdr::<PointStamped>(&bytes, "geometry_msgs/msg/PointStamped")
                .map_err(|e| e.to_string())
                .and_then(|p| target_mm(&p.point, TARGET_LIMIT_M));
            match target {
                Ok(mm) => {
                    let _ = self.command(CommandRequest::move_xyz(mm, false, 1.0), "qmarc/target");
                }
                Err(why) => self.bad_input("qmarc/target", &why),
            }
        }
        while let Ok(Some(sample)) = self.e.trajectory.try_recv() {
            let bytes = payload_of(Some(sample.payload()));
            let path = ros2::from_cdr::<JointTrajectory>(&bytes, ros2::JOINT_TRAJECTORY.name)
                .map_err(|e| e.to_string())
                .and_then(|t| self.opts.converter.path(&t));
            match path {
                Ok(path) => {
                    let _ = self.send_path(&path, "qmarc/joint_trajectory");
                }
                Err(why) => self.bad_input("qmarc/joint_trajectory", &why),
            }
        }
        while let Some(q) = self.e.stop.try_recv() {
            let reply = match ros2::from_cdr::<TriggerRequest>(&payload_of(q.payload()), "Trigger")
            {
                Err(e) => failure(&e.to_string()),
                Ok(_) => match self.command(CommandRequest::of(CommandKind::Stop), "qmarc/stop") {
                    Ok(_) => SuccessResponse { success: true, message: "stopping".into() },
                    Err(why) => failure(&why),
                },
            };
            reply_with(&self.e.stop, &q, &reply);
        }
        while let Some(q) = self.e.gripper.try_recv() {
            let reply = match ros2::from_cdr::<SetBoolRequest>(&payload_of(q.payload()), "SetBool")
            {
                Err(e) => failure(&e.to_string()),
                Ok(r) => match self.command(CommandRequest::grip(r.data), "qmarc/gripper") {
                    Ok(_) => SuccessResponse {
                        success: true,
                        message: if r.data { "closing" } else { "opening" }.into(),
                    },
                    Err(why) => failure(&why),
                },
            };
            reply_with(&self.e.gripper, &q, &reply);
        }
    }

    /// The action's turn: requests answered, the running goal watched, the goals' status
    /// published on every change (a client that joins later has the last from the
    /// publisher's cache: transient local).
    fn actions(&mut self, stamp: Time) {
        const WHAT: &str = "follow_joint_trajectory";
        while let Some(q) = self.e.action.send_goal.try_recv() {
            let accepted = match ros2::from_cdr::<SendGoalRequest>(
                &payload_of(q.payload()),
                "FollowJointTrajectory_SendGoal",
            ) {
                Err(e) => {
                    self.bad_input(WHAT, &e.to_string());
                    false
                }
                Ok(r) => self.send_goal(&r, stamp),
            };
            reply_with(&self.e.action.send_goal, &q, &SendGoalResponse { accepted, stamp });
        }
        while let Some(q) = self.e.action.cancel_goal.try_recv() {
            let reply =
                match ros2::from_cdr::<CancelGoalRequest>(&payload_of(q.payload()), "CancelGoal") {
                    Err(e) => {
                        self.bad_input(WHAT, &e.to_string());
                        CancelGoalResponse { return_code: 1, goals_canceling: Vec::new() }
                    }
                    Ok(r) => {
                        let (reply, stop) = self.goals.cancel(&r.goal_info);
                        if let Some(stop) = stop {
                            self.stop_for(stop);
                        }
                        reply
                    }
                };
            reply_with(&self.e.action.cancel_goal, &q, &reply);
        }
        while let Some(q) = self.e.action.get_result.try_recv() {
            match ros2::from_cdr::<GetResultRequest>(&payload_of(q.payload()), "GetResult") {
                Err(e) => self.bad_input(WHAT, &e.to_string()),
                Ok(r) => match self.goals.result(&r.goal_id) {
                    Some(reply) => reply_with(&self.e.action.get_result, &q, &reply),
                    None => self.waiting.push((r.goal_id, q)),
                },
            }
        }
        self.watch(stamp);
        if let Some(status) = self.goals.status_changed() {
            publish(&mut self.e.action.status, &status);
        }
    }

    /// A new goal: true if the robot took it.
    fn send_goal(&mut self, r: &SendGoalRequest, stamp: Time) -> bool {
        let goal = match self.goals.check(r, stamp) {
            Ok(goal) => goal,
            Err(why) => {
                self.bad_input("follow_joint_trajectory", &why);
                return false;
            }
        };
        let Ok(answer) = self.send_path(&goal.path, "follow_joint_trajectory") else {
            return false;
        };
        self.goals.start(goal, answer.orders.accepted, self.last.map_or(0, |s| s.cycle + 1));
        true
    }

    /// Sends the stop the goal tracker asked for.
    fn stop_for(&mut self, stop: StopFor) {
        let sent = self.command(CommandRequest::of(CommandKind::Stop), "follow_joint_trajectory");
        let finished = self.goals.stop_sent(stop, sent.ok().map(|a| a.orders.accepted));
        self.finished(finished);
    }

    /// The running goal against the robot: feedback, tolerances, its end.
    fn watch(&mut self, stamp: Time) {
        if !self.goals.running() {
            return;
        }
        let status = match self.client.send(CommandRequest::of(CommandKind::Status)) {
            Ok(s) => s,
            Err(e) => {
                let finished = self.goals.lost(format!("the controller does not answer: {e}"));
                return self.finished(finished);
            }
        };
        let motions = match (self.recent.front(), self.recent.back()) {
            (Some(first), Some(s)) => motions(first, s),
            _ => Default::default(),
        };
        let seen = Seen { fresh: &self.fresh, last: self.last.as_ref(), motions };
        let watched = self.goals.watch(&status, &seen, stamp, Instant::now());
        if let Some(feedback) = watched.feedback {
            publish(&mut self.e.action.feedback, &feedback);
        }
        if let Some(stop) = watched.stop {
            self.stop_for(stop);
        }
        self.finished(watched.finished);
    }

    /// A goal that ended: its result to every client waiting for it.
    fn finished(&mut self, finished: Option<Finished>) {
        let Some(Finished { goal_id, response }) = finished else { return };
        if response.result.error_code != FjtResult::SUCCESSFUL {
            eprintln!("qmarc-bridge: follow_joint_trajectory: {}", response.result.error_string);
        }
        for (_, q) in self.waiting.extract_if(.., |(id, _)| *id == goal_id) {
            reply_with(&self.e.action.get_result, &q, &response);
        }
    }

    /// Input from the network that is not a command: logged, in the diagnostics, never sent.
    fn bad_input(&mut self, topic: &str, why: &str) {
        eprintln!("qmarc-bridge: {topic}: not taken: {why}");
        self.refused = format!("{topic}: {why}");
    }

    /// `/diagnostics`: once a second, and at once when the state changes (the session's end
    /// included: a controller whose telemetry stopped without its last sample died).
    fn diagnose(&mut self, stamp: Time, ended: Option<&End>) {
        if self.status_at.is_none_or(|t| t.elapsed() >= Duration::from_secs(1)) {
            self.status_at = Some(Instant::now());
            if let Ok(s) = self.client.send(CommandRequest::of(CommandKind::Status)) {
                let all = (1u32 << self.opts.converter.n_motors) - 1;
                self.homed = s.robot.homed & all == all;
                let c = s.conveyor;
                self.parts = (c.active == 1).then_some([c.queued, c.picked, c.missed]);
            }
        }
        let Some(last) = self.last else { return };
        let mut state = SessionState::of(&last, self.homed, &self.refused);
        state.parts = self.parts;
        match ended {
            Some(End::Gone) if state.fault.is_empty() => {
                state.phase = "gone".into();
                state.fault = "controller_lost: the controller stopped without its last sample \
                               (it died)"
                    .into();
            }
            Some(_) if state.fault.is_empty() => state.phase = "ended".into(),
            _ => {}
        }
        let due = self.said_at.is_none_or(|t| t.elapsed() >= Duration::from_secs(1));
        if due || self.said.as_ref() != Some(&state) {
            publish(&mut self.e.diagnostics, &state.diagnostics(&self.opts.hardware_id, stamp));
            self.said = Some(state);
            self.said_at = Some(Instant::now());
        }
    }
}

/// A failed call's response.
fn failure(why: &str) -> SuccessResponse {
    SuccessResponse { success: false, message: why.to_string() }
}

/// Publishes `value`; a failure is said, never fatal (the network is not the robot's).
fn publish<T: serde::Serialize>(p: &mut RosPublisher, value: &T) {
    if let Err(e) = send_cdr(value, |b| p.put(b)) {
        eprintln!("qmarc-bridge: {}: {e}", p.keyexpr);
    }
}

/// Answers a call; a failure is said.
fn reply_with<T: serde::Serialize>(service: &RosService, q: &zenoh::query::Query, value: &T) {
    if let Err(e) = send_cdr(value, |b| service.reply(q, b)) {
        eprintln!("qmarc-bridge: {}: {e}", service.keyexpr);
    }
}

/// `value` as CDR, handed to `send`; what failed, in words.
fn send_cdr<T: serde::Serialize>(
    value: &T,
    send: impl FnOnce(Vec<u8>) -> Result<(), crate::node::ZenohError>,
) -> Result<(), String> {
    let bytes = ros2::to_cdr(value).map_err(|e| e.to_string())?;
    send(bytes).map_err(|e| e.to_string())
}
