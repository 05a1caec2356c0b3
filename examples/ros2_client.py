#!/usr/bin/env python3
"""A ROS 2 client of qmarc-bridge over Zenoh, as rmw_zenoh (ROS 2 Jazzy) speaks it, with no ROS 2
installed: PyPI's eclipse-zenoh for the transport, rosbags for the CDR and the type hashes.

    ros2_client.py [--connect tcp/HOST:PORT] [--mode peer|client] [--namespace /robot1] [--domain 0] COMMAND

Commands (each prints JSON lines):
    joint-states N      the next N joint states (name, position, velocity, effort, stamp)
    effector N          the next N effector points (m)
    diagnostics N       the next N diagnostics
    goal-status N       the next N statuses of the follow_joint_trajectory action's goals (its
                        transient-local status topic: the first is the last one published)
    target X Y Z        an online move to the point (m), published on qmarc/target
    targets N S P1 P2   N targets S seconds apart, alternating between the points P1 and P2
                        (X Y Z each, m); prints each one's send time (the benchmark's)
    raw-target N        N bytes of garbage on qmarc/target (what the bridge must refuse)
    trajectory JSON     a trajectory_msgs/msg/JointTrajectory on qmarc/joint_trajectory:
                        {"names": ["motor1", ...], "points": [{"t": 0.5, "positions": [...],
                        "velocities": [...]}, ...]} (rad, rad/s, s from the start)
    follow JSON         the qmarc/follow_joint_trajectory action (control_msgs/action/
                        FollowJointTrajectory): the trajectory's JSON as above, and optionally
                        "path_tolerance" / "goal_tolerance" ({"motor1": rad, ...} or
                        {"motor1": {"position": rad, "velocity": rad/s}, ...}), "goal_time"
                        (s), "grip_after" (s: close the gripper then), "cancel_after" (s);
                        prints whether it was accepted, the feedback received, and the result
    stop                calls qmarc/stop (std_srvs/srv/Trigger)
    gripper on|off      calls qmarc/gripper (std_srvs/srv/SetBool)
    hashes              the RIHS01 hashes rosbags computes for the message types

Without --connect it connects as a ROS 2 node does: to the Zenoh router at tcp/localhost:7447.
With --listen ENDPOINT it listens there instead (standing in for the router a bridge on
rmw_zenoh's defaults connects to). --mode client makes it a Zenoh client: everything through
the router it connects to (a host that reaches only the router).
"""

import argparse
import json
import os
import threading
import sys
import time

import numpy
import zenoh
from zenoh.ext import Int64, z_deserialize, z_serialize
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

STORE = get_typestore(Stores.ROS2_JAZZY)
# Services are not in rosbags' Jazzy store, and its RIHS01 of a service is not rosidl's (it
# counts a char as rosidl does not): these two are rosidl's, as rmw_zenoh puts them in keys.
SERVICE_HASHES = {
    "std_srvs/srv/Trigger": "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
    "std_srvs/srv/SetBool": "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a",
}
# (rosbags registers message types only: the response is named as one.)
# Trigger's and SetBool's response (rosbags registers message types only: named as one).
STORE.register(get_types_from_msg("bool success\nstring message", "std_srvs/msg/Trigger_Response"))
# FollowJointTrajectory (control_msgs 5.x, every Jazzy release) and action_msgs' CancelGoal,
# which rosbags' store lacks: their wire types, registered here (the names only look them up),
# and rosidl's hashes of the action's services and feedback, as rmw_zenoh puts them in keys.
ACTION_HASHES = {
    "send_goal": "RIHS01_b13789dddc325a7a962825c45e28c77d37237ec129dd0c34dc5994562938c57f",
    "get_result": "RIHS01_e3ceb38e3e1867c8dc0f46014df26e90eb93422f27e9e97f936e07f94be4bc8b",
    "feedback": "RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71",
    "cancel_goal": "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
}
for name, text in [
    ("control_msgs/msg/JointTolerance",
     "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration"),
    ("control_msgs/msg/JointComponentTolerance",
     "string joint_name\nuint16 component\nfloat64 position\nfloat64 velocity\nfloat64 acceleration"),
    ("control_msgs/msg/FjtGoal",
     "trajectory_msgs/msg/JointTrajectory trajectory\n"
     "trajectory_msgs/msg/MultiDOFJointTrajectory multi_dof_trajectory\n"
     "control_msgs/msg/JointTolerance[] path_tolerance\n"
     "control_msgs/msg/JointComponentTolerance[] component_path_tolerance\n"
     "control_msgs/msg/JointTolerance[] goal_tolerance\n"
     "control_msgs/msg/JointComponentTolerance[] component_goal_tolerance\n"
     "builtin_interfaces/msg/Duration goal_time_tolerance"),
    ("control_msgs/msg/FjtSendGoalRequest",
     "unique_identifier_msgs/msg/UUID goal_id\ncontrol_msgs/msg/FjtGoal goal"),
    ("control_msgs/msg/FjtSendGoalResponse", "bool accepted\nbuiltin_interfaces/msg/Time stamp"),
    ("control_msgs/msg/FjtGetResultRequest", "unique_identifier_msgs/msg/UUID goal_id"),
    ("control_msgs/msg/FjtResult", "int32 error_code\nstring error_string"),
    ("control_msgs/msg/FjtGetResultResponse", "int8 status\ncontrol_msgs/msg/FjtResult result"),
    ("control_msgs/msg/FjtFeedback",
     "std_msgs/msg/Header header\nstring[] joint_names\n"
     "trajectory_msgs/msg/JointTrajectoryPoint desired\n"
     "trajectory_msgs/msg/JointTrajectoryPoint actual\n"
     "trajectory_msgs/msg/JointTrajectoryPoint error\nstring[] multi_dof_joint_names\n"
     "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint multi_dof_desired\n"
     "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint multi_dof_actual\n"
     "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint multi_dof_error"),
    ("control_msgs/msg/FjtFeedbackMessage",
     "unique_identifier_msgs/msg/UUID goal_id\ncontrol_msgs/msg/FjtFeedback feedback"),
    ("action_msgs/msg/CancelGoalRequest", "action_msgs/msg/GoalInfo goal_info"),
    ("action_msgs/msg/CancelGoalResponse",
     "int8 return_code\naction_msgs/msg/GoalInfo[] goals_canceling"),
]:
    STORE.register(get_types_from_msg(text, name))
GID = bytes(range(16, 32))
SEQ = iter(range(1, 1 << 62))


def dds_name(typename):
    parts = typename.split("/")
    return "::".join(parts[:-1]) + "::dds_::" + parts[-1] + "_"


def keyexpr(domain, namespace, name, typename, rihs=None):
    full = name if name.startswith("/") else namespace.rstrip("/") + "/" + name
    rihs = rihs or STORE.hash_rihs01(typename)
    return f"{domain}/{full.strip('/')}/{dds_name(typename)}/{rihs}"


def attachment(seq=None):
    seq = next(SEQ) if seq is None else seq
    return z_serialize((Int64(seq), Int64(time.time_ns()), GID))


def open_session(connect, listen, mode="peer"):
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps([listen]))
    else:
        conf.insert_json5("connect/endpoints", json.dumps([connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def take(session, key, typename, n, timeout_s, show, transient_local=False):
    """Prints the next n samples on key, each with its sequence number and when it arrived
    (taken in Zenoh's callback, on the system clock); true if n arrived within timeout_s.
    transient_local: subscribed as rmw_zenoh subscribes with that durability (an advanced
    subscriber that asks the publishers' caches for the last sample each kept)."""
    got = [0]
    done = threading.Event()
    lock = threading.Lock()

    def arrived(sample):
        received_ns = time.time_ns()
        with lock:
            if got[0] >= n:
                return
            got[0] += 1
            if got[0] == n:
                done.set()
            seq, stamp_ns, gid = z_deserialize(tuple[Int64, Int64, bytes], sample.attachment)
            msg = STORE.deserialize_cdr(bytes(sample.payload.to_bytes()), typename)
            print(json.dumps(dict(show(msg), seq=int(seq), received_ns=received_ns)), flush=True)

    if transient_local:
        history = zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1)
        sub = zenoh.ext.declare_advanced_subscriber(session, key, arrived, history=history)
    else:
        sub = session.declare_subscriber(key, arrived)
    done.wait(timeout_s)
    sub.undeclare()
    with lock:
        return got[0] >= n


def call_raw(session, key, payload, typename, timeout=10.0):
    """Calls the service at key; its response, decoded, or None."""
    replies = session.get(key, payload=payload, attachment=attachment(), timeout=timeout)
    for reply in replies:
        if reply.ok is None:
            return None
        return STORE.deserialize_cdr(bytes(reply.ok.payload.to_bytes()), typename)
    return None


def follow(session, a, key, spec, timeout):
    """Runs the FollowJointTrajectory action on spec; what happened, as a dict."""
    t = STORE.types
    uuid = t["unique_identifier_msgs/msg/UUID"](uuid=numpy.frombuffer(os.urandom(16), dtype=numpy.uint8))
    bound = lambda v, what: float(v.get(what, 0.0) if isinstance(v, dict) else (v if what == "position" else 0.0))
    tolerances = lambda which: [
        t["control_msgs/msg/JointTolerance"](
            name=n, position=bound(v, "position"), velocity=bound(v, "velocity"),
            acceleration=bound(v, "acceleration"))
        for n, v in spec.get(which, {}).items()]
    goal_time = float(spec.get("goal_time", 0.0))
    empty_dof = t["trajectory_msgs/msg/MultiDOFJointTrajectory"](
        header=header(), joint_names=[], points=[])
    goal = t["control_msgs/msg/FjtGoal"](
        trajectory=STORE.deserialize_cdr(joint_trajectory(spec), "trajectory_msgs/msg/JointTrajectory"),
        multi_dof_trajectory=empty_dof, path_tolerance=tolerances("path_tolerance"),
        component_path_tolerance=[], goal_tolerance=tolerances("goal_tolerance"),
        component_goal_tolerance=[],
        goal_time_tolerance=t["builtin_interfaces/msg/Duration"](
            sec=int(goal_time), nanosec=int(round((goal_time - int(goal_time)) * 1e9))))
    action = "qmarc/follow_joint_trajectory/_action/"
    feedback = []
    fb_key = key(action + "feedback", "control_msgs/action/FollowJointTrajectory_FeedbackMessage",
                 ACTION_HASHES["feedback"])
    sub = session.declare_subscriber(fb_key, lambda s: feedback.append(
        STORE.deserialize_cdr(bytes(s.payload.to_bytes()), "control_msgs/msg/FjtFeedbackMessage")))
    # Once the action's server and its feedback publisher are known (their tokens), as
    # rclcpp's wait_for_action_server.
    for kind, entity in [("SS", "send_goal"), ("SS", "get_result"), ("MP", "feedback")]:
        if not wait_for_entity(session, a.domain, a.namespace, kind, action + entity, timeout):
            sub.undeclare()
            return {"accepted": False, "error": f"no {action + entity} within {timeout} s"}
    request = t["control_msgs/msg/FjtSendGoalRequest"](goal_id=uuid, goal=goal)
    answer = call_raw(
        session, key(action + "send_goal", "control_msgs/action/FollowJointTrajectory_SendGoal",
                     ACTION_HASHES["send_goal"]),
        bytes(STORE.serialize_cdr(request, "control_msgs/msg/FjtSendGoalRequest")),
        "control_msgs/msg/FjtSendGoalResponse")
    out = {"accepted": bool(answer and answer.accepted)}
    if not out["accepted"]:
        sub.undeclare()
        return out
    if "grip_after" in spec:
        # The gripper closed on the way (a pick on the fly): the goal goes on.
        time.sleep(float(spec["grip_after"]))
        grip = call_raw(session, key("qmarc/gripper", "std_srvs/srv/SetBool",
                                     SERVICE_HASHES["std_srvs/srv/SetBool"]),
                        b"\x00\x01\x00\x00\x01", "std_srvs/msg/Trigger_Response")
        out["grip_success"] = bool(grip and grip.success)
    if "cancel_after" in spec:
        time.sleep(float(spec["cancel_after"]))
        info = t["action_msgs/msg/GoalInfo"](goal_id=uuid, stamp=t["builtin_interfaces/msg/Time"](sec=0, nanosec=0))
        cancel = call_raw(
            session, key(action + "cancel_goal", "action_msgs/srv/CancelGoal", ACTION_HASHES["cancel_goal"]),
            bytes(STORE.serialize_cdr(t["action_msgs/msg/CancelGoalRequest"](goal_info=info),
                                      "action_msgs/msg/CancelGoalRequest")),
            "action_msgs/msg/CancelGoalResponse")
        out["cancel_return_code"] = int(cancel.return_code) if cancel else None
    result = call_raw(
        session, key(action + "get_result", "control_msgs/action/FollowJointTrajectory_GetResult",
                     ACTION_HASHES["get_result"]),
        bytes(STORE.serialize_cdr(t["control_msgs/msg/FjtGetResultRequest"](goal_id=uuid),
                                  "control_msgs/msg/FjtGetResultRequest")),
        "control_msgs/msg/FjtGetResultResponse", timeout=timeout)
    sub.undeclare()
    mine = [f for f in feedback if bytes(f.goal_id.uuid) == bytes(uuid.uuid)]
    out.update(status=int(result.status) if result else None,
               error_code=int(result.result.error_code) if result else None,
               error_string=result.result.error_string if result else None,
               feedback=len(mine),
               joint_names=list(mine[-1].feedback.joint_names) if mine else [],
               max_error=max((abs(float(e)) for f in mine for e in f.feedback.error.positions), default=0.0))
    return out


def mangle(name):
    return name.replace("/", "%")


def wait_for_entity(session, domain, namespace, kind, name, timeout_s):
    """Waits until the ROS graph has an entity of kind (SS a service server, MS a
    subscription, MP a publisher) on name, as rmw_zenoh's graph cache learns it: from the
    liveliness tokens its session has been told of (a liveliness subscriber with history).
    True if it came within timeout_s. What rmw_zenoh's service_server_is_available and a
    publisher's matching do: a call made before the server is known goes nowhere."""
    full = name if name.startswith("/") else namespace.rstrip("/") + "/" + name
    pattern = f"@ros2_lv/{domain}/*/*/*/{kind}/*/*/*/{mangle(full)}/**"
    seen = threading.Event()
    sub = session.liveliness().declare_subscriber(pattern, lambda s: seen.set(), history=True)
    found = seen.wait(timeout_s)
    sub.undeclare()
    return found


def call(session, key, payload, typename):
    replies = session.get(key, payload=payload, attachment=attachment(), timeout=10.0)
    for reply in replies:
        if reply.ok is None:
            print(json.dumps({"error": str(reply.err.payload.to_string())}), flush=True)
            return False
        seq, _, gid = z_deserialize(tuple[Int64, Int64, bytes], reply.ok.attachment)
        msg = STORE.deserialize_cdr(bytes(reply.ok.payload.to_bytes()), typename)
        print(json.dumps({"success": bool(msg.success), "message": msg.message,
                          "seq": int(seq), "gid_echoed": bytes(gid) == GID}), flush=True)
        return bool(msg.success)
    print(json.dumps({"error": "no reply"}), flush=True)
    return False


def publisher(session, key, timeout_s=20.0):
    """A reliable publisher on key (it waits rather than drop on a busy link, as a reliable
    ROS 2 publisher's history does), once it matches a subscriber (the bridge's), or
    timeout_s has passed."""
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + timeout_s
    while not pub.matching_status.matching and time.monotonic() < deadline:
        time.sleep(0.01)
    return pub


def publish(session, key, payload):
    """Publishes one sample on key, and gives it time to leave before the session closes."""
    publisher(session, key).put(payload, attachment=attachment())
    time.sleep(1.0)


def header(frame_id=""):
    """A std_msgs/msg/Header stamped 0 (the bridge does not wait for a stamp)."""
    t = STORE.types
    return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                    frame_id=frame_id)


def point_stamped(xyz):
    """A geometry_msgs/msg/PointStamped of the point xyz (m) in the base frame, as CDR."""
    t = STORE.types
    msg = t["geometry_msgs/msg/PointStamped"](
        header=header("base"), point=t["geometry_msgs/msg/Point"](*map(float, xyz)))
    return bytes(STORE.serialize_cdr(msg, "geometry_msgs/msg/PointStamped"))


def joint_trajectory(spec):
    """The JointTrajectory of a JSON spec, as CDR."""
    t = STORE.types
    points = []
    for p in spec["points"]:
        sec = int(p["t"])
        points.append(t["trajectory_msgs/msg/JointTrajectoryPoint"](
            positions=numpy.array(p["positions"], dtype=numpy.float64),
            velocities=numpy.array(p.get("velocities", []), dtype=numpy.float64),
            accelerations=numpy.array([], dtype=numpy.float64),
            effort=numpy.array([], dtype=numpy.float64),
            time_from_start=t["builtin_interfaces/msg/Duration"](
                sec=sec, nanosec=int(round((p["t"] - sec) * 1e9)))))
    msg = t["trajectory_msgs/msg/JointTrajectory"](
        header=header(), joint_names=list(spec["names"]), points=points)
    return bytes(STORE.serialize_cdr(msg, "trajectory_msgs/msg/JointTrajectory"))


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", default="tcp/localhost:7447")
    p.add_argument("--listen", default=None)
    p.add_argument("--mode", default="peer", choices=["peer", "client"])
    p.add_argument("--namespace", default="")
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--timeout", type=float, default=20.0)
    p.add_argument("--repeat", type=int, default=1,
                   help="stop, gripper: make the call this many times, each from a new session")
    p.add_argument("command", choices=COMMANDS, metavar="COMMAND",
                   help="one of: " + ", ".join(COMMANDS))
    # The command's arguments as typed: a coordinate such as -1e9 is one, not an option.
    p.add_argument("args", nargs=argparse.REMAINDER)
    a = p.parse_args()
    # Options given after the command are options still (`joint-states 10 --timeout=30`);
    # the rest are the command's arguments as typed.
    options = {o for action in p._actions for o in action.option_strings}
    rest, later = [], []
    words = iter(a.args)
    for word in words:
        if word.split("=")[0] in options:
            later.append(word)
            if "=" not in word:
                later.append(next(words, ""))
        else:
            rest.append(word)
    if later:
        p.parse_args(later + [a.command], namespace=a)
    a.args = rest
    if a.command == "hashes":
        for t in ["sensor_msgs/msg/JointState", "geometry_msgs/msg/PointStamped",
                  "diagnostic_msgs/msg/DiagnosticArray", "trajectory_msgs/msg/JointTrajectory"]:
            print(json.dumps({"type": t, "rihs01": STORE.hash_rihs01(t)}))
        return 0
    wanted = ARGUMENTS[a.command]
    if len(a.args) != wanted:
        p.error(f"{a.command} takes {wanted} argument{'s' * (wanted != 1)}, found {len(a.args)}")
    if a.command in ("target", "targets"):
        try:
            [float(v) for v in a.args]
        except ValueError as e:
            p.error(f"{a.command}: {e}")
    if a.command in ("stop", "gripper"):
        ok = all(service_call(a) for _ in range(max(a.repeat, 1)))
        return 0 if ok else 1
    session = opened(a)
    key = lambda name, t, rihs=None: keyexpr(a.domain, a.namespace, name, t, rihs)
    ok = True
    if a.command == "joint-states":
        ok = take(session, key("joint_states", "sensor_msgs/msg/JointState"),
                  "sensor_msgs/msg/JointState", int(a.args[0]), a.timeout,
                  lambda m: {"name": list(m.name), "position": list(map(float, m.position)),
                             "velocity": list(map(float, m.velocity)),
                             "effort": list(map(float, m.effort)),
                             "stamp_ns": m.header.stamp.sec * 10**9 + m.header.stamp.nanosec})
    elif a.command == "effector":
        ok = take(session, key("qmarc/effector", "geometry_msgs/msg/PointStamped"),
                  "geometry_msgs/msg/PointStamped", int(a.args[0]), a.timeout,
                  lambda m: {"frame": m.header.frame_id,
                             "point": [m.point.x, m.point.y, m.point.z]})
    elif a.command == "goal-status":
        ok = take(session, key("qmarc/follow_joint_trajectory/_action/status",
                               "action_msgs/msg/GoalStatusArray"),
                  "action_msgs/msg/GoalStatusArray", int(a.args[0]), a.timeout,
                  lambda m: {"status": [int(g.status) for g in m.status_list]},
                  transient_local=True)
    elif a.command == "diagnostics":
        ok = take(session, key("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
                  "diagnostic_msgs/msg/DiagnosticArray", int(a.args[0]), a.timeout,
                  lambda m: {"level": int(m.status[0].level), "message": m.status[0].message,
                             "values": {kv.key: kv.value for kv in m.status[0].values}})
    elif a.command == "target":
        k = key("qmarc/target", "geometry_msgs/msg/PointStamped")
        publish(session, k, point_stamped(a.args[:3]))
        print(json.dumps({"published": k}), flush=True)
    elif a.command == "targets":
        # N targets, every S seconds, alternating between two points: each one's time sent.
        n, every = int(a.args[0]), float(a.args[1])
        points = [list(map(float, a.args[2:5])), list(map(float, a.args[5:8]))]
        k = key("qmarc/target", "geometry_msgs/msg/PointStamped")
        pub = publisher(session, k)
        for i in range(n):
            payload = point_stamped(points[i % 2])
            sent = time.time_ns()
            pub.put(payload, attachment=attachment())
            print(json.dumps({"published_ns": sent}), flush=True)
            time.sleep(every)
    elif a.command == "raw-target":
        k = key("qmarc/target", "geometry_msgs/msg/PointStamped")
        publish(session, k, bytes([0x00, 0x01, 0x00, 0x00]) + bytes(int(a.args[0])))
        print(json.dumps({"published": k, "bytes": int(a.args[0]) + 4}), flush=True)
    elif a.command == "trajectory":
        k = key("qmarc/joint_trajectory", "trajectory_msgs/msg/JointTrajectory")
        publish(session, k, joint_trajectory(json.loads(a.args[0])))
        print(json.dumps({"published": k}), flush=True)
    elif a.command == "follow":
        out = follow(session, a, key, json.loads(a.args[0]), a.timeout)
        print(json.dumps(out), flush=True)
        ok = not out["accepted"] or out.get("status") is not None
    session.close()
    return 0 if ok else 1


def opened(a):
    """The session of the command line's options, or an exit saying why there is none."""
    try:
        return open_session(a.connect, a.listen, a.mode)
    except zenoh.ZError as e:
        where = a.listen or a.connect
        print(json.dumps({"error": f"cannot open a Zenoh session with {where}: {e}"}), flush=True)
        sys.exit(1)


def service_call(a):
    """One call of the stop or gripper service from a session of its own, made once the
    service's server is known (its liveliness token); true if it succeeded."""
    session = opened(a)
    try:
        if a.command == "stop":
            name, typename, payload = "qmarc/stop", "std_srvs/srv/Trigger", b"\x00\x01\x00\x00\x00"
        else:
            if a.args[0] not in ("on", "off"):
                print(json.dumps({"error": f"gripper takes on or off, found {a.args[0]}"}), flush=True)
                return False
            name, typename = "qmarc/gripper", "std_srvs/srv/SetBool"
            payload = b"\x00\x01\x00\x00" + bytes([a.args[0] == "on"])
        if not wait_for_entity(session, a.domain, a.namespace, "SS", name, a.timeout):
            print(json.dumps({"error": f"no server of {name} within {a.timeout} s"}), flush=True)
            return False
        k = keyexpr(a.domain, a.namespace, name, typename, SERVICE_HASHES[typename])
        return call(session, k, payload, "std_srvs/msg/Trigger_Response")
    finally:
        session.close()


# Every command and how many arguments it takes.
ARGUMENTS = {"joint-states": 1, "effector": 1, "diagnostics": 1, "goal-status": 1, "target": 3,
             "targets": 8, "raw-target": 1, "trajectory": 1, "follow": 1, "stop": 0,
             "gripper": 1, "hashes": 0}
COMMANDS = list(ARGUMENTS)



if __name__ == "__main__":
    sys.exit(main())
