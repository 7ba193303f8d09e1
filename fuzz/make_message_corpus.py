#!/usr/bin/env python3
"""Writes the seed corpus of the message fuzzer (fuzz/corpus/messages/): one valid message per
type of docs/protocol.md, a few near misses, and camera frames. Run from anywhere; idempotent."""
import json
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "corpus", "messages")

POSE = {"position": [0.1, 0.2, 0.0], "quaternion_wxyz": [1.0, 0.0, 0.0, 0.0]}
EXAMPLES = {
    "hello": {"client": "operator-site", "protocol": 1},
    "welcome": {"session": 3, "protocol": 1, "server": "worksite", "lease_holder": None,
                "heartbeat_period_s": 0.05, "link_timeout_s": 0.25},
    "heartbeat": {"t_s": 1.5, "echo_t_s": 1.2, "hold_s": 0.01},
    "error": {"code": "invalid_field", "message": "x: missing", "in_reply_to": 4},
    "lease_request": {},
    "lease_grant": {"granted": False, "holder": 2, "reason": "held by session 2"},
    "lease_release": {},
    "lease_state": {"holder": 2, "generation": 5},
    "link_state": {"state": "lost", "stopped": True, "reason": "silent for 0.26 s", "silent_s": 0.26},
    "resume": {},
    "recognitions": {"frame_seq": 17, "camera": 0,
                     "objects": [{"model": "cube45", "world_T_object": POSE, "score": 0.83}]},
    "robot_state": {"t_s": 12.0, "joints_rad": [0, 0.1, 0.2, 0.3, 0.4, 0.5], "world_T_tool": POSE,
                    "force_n": [0, 0, -1.5], "torque_nm": [0, 0, 0], "gripper_width_m": 0.05,
                    "moving": False, "stopped": False},
    "program_submit": {"program_id": "p1", "program": {"commands": []}},
    "execution_progress": {"program_id": "p1", "command_index": 2, "command_count": 5, "state": "running"},
    "report": {"program_id": "p1", "ok": True, "report": {"commands": []}},
    "reset_world": {},
    "dragger_input": {"object": "cube45", "phase": "move", "world_T_dragger": POSE},
    "pose_update": {"t_s": 3.0, "poses": [{"object": "cube45", "world_T_object": POSE}], "sim_rate_hz": 240.0},
    "console_command": {"line": "select cube45"},
    "console_output": {"text": "selected cube45", "ok": True, "in_reply_to": 9},
    "session_save": {"name": "corner-demo_1"},
    "session_load": {"name": "corner-demo_1"},
    "world_state": {"revision": 4,
                    "objects": [{"name": "cube", "fixed": False, "model": "cube45",
                                 "shape": {"box": [0.045, 0.045, 0.045]}, "world_T_object": POSE,
                                 "origin": "scene"}],
                    "workpiece": "cube", "capture": ["frame"], "dragging": False, "demonstrations": 1,
                    "models": [{"name": "cube45", "shape": {"box": [0.045, 0.045, 0.045]}}],
                    "cameras": [], "robot": None,
                    "link": {"state": "up", "stopped": False, "reason": "connected", "rtt_s": None},
                    "lease_holder": 1, "busy": "",
                    "paths": {"initial": [POSE, POSE], "deformed": [], "simplified": []},
                    "program": {"id": "p1", "command_count": 3, "listing": "1 grasp"},
                    "report": None, "sim_rate_hz": 60.5},
    "worksite_scene": {"scene": {"objects": []},
                       "models": [{"name": "cube45", "shape": {"box": [0.045, 0.045, 0.045]}}]},
}


def write(name, data):
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(os.path.join(OUT, name), mode) as f:
        f.write(data)


def frame(seq, width, height, fmt, camera=0, stamp=0.5):
    channels = {1: 1, 2: 3}[fmt]
    header = b"TSB1" + struct.pack("<BBHQIId", 10, fmt, camera, seq, width, height, stamp)
    assert len(header) == 32
    return header + bytes((i * 7) % 256 for i in range(width * height * channels))


def main():
    os.makedirs(OUT, exist_ok=True)
    for seq, (kind, fields) in enumerate(EXAMPLES.items(), start=1):
        write(f"{kind}.json", json.dumps(dict({"type": kind, "seq": seq}, **fields)))
    # Near misses: each one step from valid.
    write("near-missing-field.json", json.dumps({"type": "dragger_input", "seq": 2, "object": "cube", "phase": "move"}))
    write("near-unknown-type.json", json.dumps({"type": "self_destruct", "seq": 2}))
    write("near-bad-quaternion.json", json.dumps({"type": "dragger_input", "seq": 2, "object": "c", "phase": "move",
                                                  "world_T_dragger": {"position": [0, 0, 0],
                                                                      "quaternion_wxyz": [1, 1, 0, 0]}}))
    write("near-truncated.json", '{"type": "console_command", "seq": 3, "line": "he')
    write("frame-gray8-8x4.bin", frame(1, 8, 4, 1))
    write("frame-rgb8-4x4.bin", frame(2, 4, 4, 2, camera=1))


if __name__ == "__main__":
    main()
