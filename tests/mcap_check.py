#!/usr/bin/env python3
"""Checks a move's gather.mcap against its gather.csv with the MCAP ecosystem's own readers
(PyPI: mcap, mcap-ros2-support, mcap-protobuf-support) and rosbags' ROS 2 message
definitions (issue 45), independently of the Rust that wrote it:

- the file is a rosbag2-style MCAP: profile `ros2`, a Statistics record, every channel with
  a schema;
- /qmarc/gather: one JSON message per gather.csv row, with exactly its columns, in order, and
  its values; log time = tick 0 + the row's time_s;
- /joint_states: sensor_msgs/msg/JointState in CDR, its ros2msg schema byte for byte the text
  rosbags generates for ROS 2; names motor1..N; positions = the row's act / counts_per_rad
  (summary.json); the DAC's volts as effort;
- /qmarc/effector: its distance is |cmd - act|;
- /qmarc/scene: foxglove.SceneUpdate at >= 25 Hz of loop time, the robot in every one;
- /qmarc/log: foxglove.Log, printed.

Usage: mcap_check.py OUT_DIR. Prints one JSON line of what it found; exits 1 naming the
first difference."""

import csv
import json
import math
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoder
from mcap_ros2.decoder import DecoderFactory as Ros2Decoder
from rosbags.typesys import Stores, get_typestore


def fail(why):
    print(f"mcap_check: {why}", file=sys.stderr)
    sys.exit(1)


def main():
    out = Path(sys.argv[1])
    with open(out / "gather.csv", newline="") as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    summary = json.loads((out / "summary.json").read_text())
    counts_per_rad = summary["counts_per_rad"]
    n = summary["n_motors"]
    col = {c: i for i, c in enumerate(header)}

    with open(out / "gather.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[Ros2Decoder(), ProtobufDecoder()])
        h = reader.get_header()
        if h.profile != "ros2":
            fail(f"profile {h.profile!r}, not ros2")
        s = reader.get_summary()
        if s is None or s.statistics is None:
            fail("no summary with statistics (ros2 bag info needs them)")
        topics = {}
        for ch in s.channels.values():
            if ch.schema_id == 0 or ch.schema_id not in s.schemas:
                fail(f"channel {ch.topic} has no schema")
            sc = s.schemas[ch.schema_id]
            topics[ch.topic] = (sc.name, sc.encoding, ch.message_encoding, sc.data)

        ros2 = get_typestore(Stores.ROS2_JAZZY)
        msgdef, _ = ros2.generate_msgdef("sensor_msgs/msg/JointState", ros_version=2)
        js = topics.get("/joint_states")
        if js is None or js[:3] != ("sensor_msgs/msg/JointState", "ros2msg", "cdr"):
            fail(f"/joint_states is {js and js[:3]}")
        if js[3].decode() != msgdef:
            fail("the JointState schema is not the ROS 2 definition rosbags gives")

        found = {"rows": 0, "joint_states": 0, "effector": 0, "scenes": 0, "log": []}
        by_time = {}
        t0 = None
        scene_times = []
        max_pos_err = 0.0
        for schema, channel, message in reader.iter_messages():
            topic = channel.topic
            if topic == "/qmarc/gather":
                k = found["rows"]
                if k >= len(rows):
                    fail(f"more gather messages than gather.csv's {len(rows)} rows")
                v = json.loads(message.data)
                if list(v.keys()) != header:
                    fail(f"row {k}: keys {list(v.keys())} are not gather.csv's {header}")
                for c, text in zip(header, rows[k]):
                    if float(v[c]) != float(text):
                        fail(f"row {k} column {c}: {v[c]} in the MCAP, {text} in gather.csv")
                if "time_s" in col:
                    t_ns = round(float(rows[k][col["time_s"]]) * 1e9)
                    if t0 is None:
                        t0 = message.log_time - t_ns
                    if abs(message.log_time - (t0 + t_ns)) > 1:
                        fail(f"row {k}: log time {message.log_time}, not tick 0 + time_s")
                by_time[message.log_time] = rows[k]
                found["rows"] += 1
            elif topic == "/joint_states":
                msg = Ros2Decoder().decoder_for("cdr", schema)(message.data)
                names = [f"motor{m}" for m in range(1, n + 1)]
                if list(msg.name) != names:
                    fail(f"joint names {list(msg.name)}")
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                if stamp != message.log_time:
                    fail(f"joint state stamped {stamp}, logged {message.log_time}")
                row = by_time.get(message.log_time)
                if row is None:
                    fail(f"a joint state at {message.log_time} with no row at that time")
                for m in range(n):
                    act = float(row[col[f"act{m + 1}"]]) / counts_per_rad
                    max_pos_err = max(max_pos_err, abs(msg.position[m] - act))
                    if "dac1" in col:
                        volts = int(row[col[f"dac{m + 1}"]]) * 10.0 / 8191
                        if abs(msg.effort[m] - volts) > 1e-12:
                            fail(f"effort {msg.effort[m]} V, the row's DAC is {volts} V")
                found["joint_states"] += 1
            elif topic == "/qmarc/effector":
                v = json.loads(message.data)
                d = math.dist([v["cmd"][a] for a in "xyz"], [v["act"][a] for a in "xyz"])
                if abs(d - v["error_mm"]) > 1e-9:
                    fail(f"effector error {v['error_mm']} mm, |cmd - act| is {d}")
                found["effector"] += 1
            elif topic == "/qmarc/scene":
                msg = ProtobufDecoder().decoder_for("protobuf", schema)(message.data)
                ids = [e.id for e in msg.entities]
                if "deltabot" not in ids:
                    fail(f"a scene without the robot: {ids}")
                found.setdefault("entities", sorted(set(ids) | set(found.get("entities", []))))
                found["entities"] = sorted(set(ids) | set(found["entities"]))
                belt = [e for e in msg.entities if e.id == "belt"]
                found["max_parts"] = max(found.get("max_parts", 0), len(belt[0].cubes) - 1 if belt else 0)
                scene_times.append(message.log_time)
                found["scenes"] += 1
            elif topic == "/qmarc/log":
                msg = ProtobufDecoder().decoder_for("protobuf", schema)(message.data)
                found["log"].append([msg.level, msg.message])
        if found["rows"] != len(rows):
            fail(f"{found['rows']} gather messages for gather.csv's {len(rows)} rows")
        span = (scene_times[-1] - scene_times[0]) / 1e9 if len(scene_times) > 1 else 0.0
        found["scene_hz"] = (len(scene_times) - 1) / span if span > 0 else 0.0
        found["max_position_error_rad"] = max_pos_err
        found["topics"] = sorted(topics)
        found["message_count"] = s.statistics.message_count
        print(json.dumps(found))


if __name__ == "__main__":
    main()
