#!/usr/bin/env python3
"""Writes scenes/puzzle.json, the default scene (docs/formats.md). Run from the repository root."""
import json
import math


def quat_z(deg):
    a = math.radians(deg) / 2
    return [math.cos(a), 0.0, 0.0, math.sin(a)]


def pose(p, q=(1.0, 0.0, 0.0, 0.0)):
    return {"position": list(p), "quaternion_wxyz": list(q)}


def box(s):
    return {"box": list(s)}


def matrix_to_quat(r):
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return [s / 4, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s]
    i = max(range(3), key=lambda k: r[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + r[i][i] - r[j][j] - r[k][k]) * 2
    q = [0.0] * 4
    q[0] = (r[k][j] - r[j][k]) / s
    q[1 + i] = s / 4
    q[1 + j] = (r[j][i] + r[i][j]) / s
    q[1 + k] = (r[k][i] + r[i][k]) / s
    return q


def look_at(eye, target, up=(0, 0, 1)):
    """world_T_camera for OpenCV axes: z forward, x right, y down."""
    def norm(v):
        n = math.sqrt(sum(c * c for c in v))
        return [c / n for c in v]

    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    z = norm([t - e for t, e in zip(target, eye)])
    x = norm(cross(z, up))
    y = cross(z, x)
    r = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]
    return matrix_to_quat(r)


H = 0.03  # frame wall height, as in ../shared/data/vision-dev (a gripper holds a 45 mm block above it)
# Movable blocks rest 0.25 mm above the table: within the contact distance (0.5 mm), outside the
# barrier distance (0.1 mm) that the simulator keeps between objects (paper §5.2).
REST = 0.00025
frame_parts = [
    {"shape": box([0.24, 0.02, H]), "pose": pose([0.0, -0.09, H / 2])},
    {"shape": box([0.24, 0.02, H]), "pose": pose([0.0, 0.09, H / 2])},
    {"shape": box([0.02, 0.16, H]), "pose": pose([-0.11, 0.0, H / 2])},
    {"shape": box([0.02, 0.16, H]), "pose": pose([0.11, 0.0, H / 2])},
    # A post raises the west wall by the south-west inside corner to 55 mm, and its lip overhangs
    # the inside by 12 mm, 5 mm above the top of a 45 mm block in that corner: a block lowered
    # straight into the corner snags on it (paper Figure 11); one slid in from the open side does
    # not, and the gripper's fingers (on the block's north and south faces) pass beside it.
    {"shape": box([0.02, 0.06, 0.025]), "pose": pose([-0.11, -0.05, H + 0.0125])},
    {"shape": box([0.012, 0.06, 0.005]), "pose": pose([-0.094, -0.05, 0.0525])},
]
objects = [
    {"name": "table", "fixed": True, "shape": box([0.8, 0.6, 0.05]), "pose": pose([0.0, 0.0, -0.025])},
    {"name": "frame", "fixed": True, "shape": {"parts": frame_parts}, "pose": pose([0.0, 0.0, 0.0])},
    {"name": "cube", "fixed": False, "model": "cube45", "shape": box([0.045, 0.045, 0.045]),
     "pose": pose([0.03, 0.02, 0.0225 + REST], quat_z(20))},
    {"name": "bar", "fixed": False, "model": "bar90", "shape": box([0.09, 0.045, 0.045]),
     "pose": pose([0.19, 0.05, 0.0225 + REST], quat_z(90))},
    {"name": "tall", "fixed": False, "model": "tall135", "shape": box([0.045, 0.045, 0.135]),
     "pose": pose([-0.185, 0.07, 0.0675 + REST])},
    {"name": "plate", "fixed": False, "model": "plate15", "shape": box([0.06, 0.06, 0.015]),
     "pose": pose([0.19, -0.09, 0.0075 + REST], quat_z(-15))},
    {"name": "slab", "fixed": False, "model": "slab", "shape": box([0.09, 0.06, 0.03]),
     "pose": pose([-0.19, -0.08, 0.015 + REST], quat_z(90))},
]
eye = [0.06, 0.46, 0.5]
camera = {"name": "main", "width": 640, "height": 480, "fx": 764.0, "fy": 764.0, "cx": 319.5, "cy": 239.5,
          "k1": -0.24, "k2": 0.006, "p1": 0.0, "p2": 0.0, "k3": 0.0,
          "position": eye, "quaternion_wxyz": look_at(eye, [0.0, -0.01, 0.0])}
scene = {"objects": objects, "cameras": [camera],
         "robot": {"model": "crs_a465", "base": pose([0.0, -0.36, 0.0], quat_z(90))}}
with open("scenes/puzzle.json", "w") as f:
    json.dump(scene, f, indent=2)
    f.write("\n")
