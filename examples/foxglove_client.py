#!/usr/bin/env python3
"""A viewer of QMARC's live view with no Foxglove: the Foxglove WebSocket protocol
(`foxglove.websocket.v1`, as Foxglove's app and PlotJuggler speak it) from PyPI's
`websockets`, the scene decoded with `protobuf` from the schema the server advertises, the
joint states with rosbags' CDR codec (issue 45; the tests and `qmarc-bench foxglove` use it).

    foxglove_client.py [--url ws://127.0.0.1:8765] [--seconds 3] [--topics T,…] [--hang]
                       [--count-only] [--ready FILE]

Connects (trying again for 30 s), reads the server's advertisements, subscribes to `--topics`
(default: all), and for `--seconds` from then counts what arrives (`--ready FILE`: creates
FILE once subscribed); then prints one JSON line: the subprotocol agreed, the
topics advertised, the messages per topic, the scene's entities, the last joint state and
the log's lines. `--hang` subscribes and then never reads again (a viewer that stopped),
until it is killed."""

import argparse
import base64
import json
import struct
import sys
import time

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from rosbags.typesys import Stores, get_typestore
from websockets.exceptions import ConnectionClosed, InvalidHandshake
from websockets.sync.client import connect


def protobuf_class(schema_name, schema_b64):
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def connected(url, subprotocol, patience=30.0):
    """The connection to the live view at `url`, tried again for `patience` seconds: on a
    loaded machine an opening handshake can time out or a listener be not yet there."""
    deadline = time.monotonic() + patience
    while True:
        try:
            return connect(url, subprotocols=[subprotocol], max_size=None, open_timeout=10,
                           proxy=None)
        except (OSError, TimeoutError, InvalidHandshake) as e:
            if time.monotonic() > deadline:
                raise SystemExit(f"foxglove_client: cannot connect to {url}: {e}")
            time.sleep(0.2)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--url", default="ws://127.0.0.1:8765")
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--topics", default="")
    ap.add_argument("--subprotocol", default="foxglove.websocket.v1")
    ap.add_argument("--hang", action="store_true")
    ap.add_argument("--ready", default="",
                    help="a file to create once subscribed (for a caller to wait on)")
    ap.add_argument("--count-only", action="store_true",
                    help="count the messages, decode none (a viewer elsewhere: the benchmark)")
    a = ap.parse_args()
    ros2 = get_typestore(Stores.ROS2_JAZZY)
    found = {"counts": {}, "entities": [], "log": [], "advertised": []}
    with connected(a.url, a.subprotocol) as ws:
        found["subprotocol"] = ws.subprotocol
        channels, subscribed, decoders, last = {}, {}, {}, {}
        wanted = set(t for t in a.topics.split(",") if t)
        # The seconds count from the subscription (connecting may take a while).
        deadline = time.monotonic() + 30 + a.seconds
        next_id = 1
        while time.monotonic() < deadline:
            try:
                msg = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
            except TimeoutError:
                break
            except ConnectionClosed:
                # The session ended (the live view with it): what came until then.
                found["closed"] = True
                break
            if isinstance(msg, str):
                op = json.loads(msg)
                if op.get("op") == "advertise":
                    subs = []
                    for ch in op["channels"]:
                        channels[ch["id"]] = ch
                        found["advertised"].append(ch["topic"])
                        if wanted and ch["topic"] not in wanted:
                            continue
                        subscribed[next_id] = ch
                        subs.append({"id": next_id, "channelId": ch["id"]})
                        next_id += 1
                    if subs:
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                        deadline = time.monotonic() + a.seconds
                        if a.ready:
                            open(a.ready, "w").close()
                    if a.hang:
                        print(json.dumps({"hanging": True}), flush=True)
                        while True:
                            time.sleep(3600)
                continue
            if msg[0] != 0x01:
                continue
            sub, log_time = struct.unpack_from("<IQ", msg, 1)
            payload = msg[13:]
            ch = subscribed.get(sub)
            if ch is None:
                continue
            topic = ch["topic"]
            found["counts"][topic] = found["counts"].get(topic, 0) + 1
            if a.count_only:
                continue
            if ch["encoding"] == "protobuf":
                cls = decoders.get(topic) or protobuf_class(ch["schemaName"], ch["schema"])
                decoders[topic] = cls
                m = cls.FromString(payload)
                if topic == "/qmarc/scene":
                    ids = sorted(e.id for e in m.entities)
                    found["entities"] = sorted(set(found["entities"]) | set(ids))
                    # The belt's first cube is the belt, the others its parts.
                    for e in m.entities:
                        if e.id == "belt":
                            found["max_parts"] = max(found.get("max_parts", 0), len(e.cubes) - 1)
                elif topic == "/qmarc/log":
                    found["log"].append([m.level, m.message])
            else:
                # The last of each: decoded once at the end, so that the viewer keeps up.
                last[topic] = (ch, log_time, payload)
    for topic, (ch, log_time, payload) in last.items():
        if ch["encoding"] == "cdr":
            js = ros2.deserialize_cdr(payload, "sensor_msgs/msg/JointState")
            found["joint_state"] = {
                "name": list(js.name),
                "position": [float(p) for p in js.position],
                "stamp_ns": js.header.stamp.sec * 1_000_000_000 + js.header.stamp.nanosec,
                "log_time": log_time,
            }
        elif ch["encoding"] == "json":
            found["last_" + topic.rsplit("/", 1)[-1]] = json.loads(payload)
    found["advertised"] = sorted(set(found["advertised"]))
    print(json.dumps(found), flush=True)


if __name__ == "__main__":
    sys.exit(main())
