"""Scenes for the benches: many boxes off the arm's path, and a point cloud of a cluttered desk.

Both are made from a seed (same seed, same scene) and are plain data: box dicts as a plan writes them, points
(N, 3) in m. The desk is what a depth camera above it would see: the desk top and the outer surfaces of the
things on it (books, a mug, a monitor stand, a box of parts), each point on a surface, none inside.
"""

from __future__ import annotations

import numpy as np

DESK = (-0.25, 0.55, -0.30, 0.30)  # x0, x1, y0, y1 (m): the table of the bundled plans
# (kind, centre x, y, size x, y, z | radius, height): kept clear of the pick (0.25, -0.15) and place (0.25, 0.15)
CLUTTER = [
    ("box", -0.18, 0.0, 0.06, 0.26, 0.22),   # monitor stand behind the arm
    ("box", 0.47, -0.02, 0.10, 0.14, 0.035),  # books
    ("box", 0.47, -0.02, 0.09, 0.12, 0.025, 0.035),  # the book on top (z offset)
    ("cyl", 0.06, 0.24, 0.04, 0.09),          # mug
    ("cyl", 0.48, 0.22, 0.03, 0.12),          # bottle
    ("box", -0.12, -0.22, 0.10, 0.08, 0.05),  # box of parts
    ("box", 0.05, -0.25, 0.06, 0.04, 0.02),   # phone
]


def boxes_off_path(n: int = 200, seed: int = 0, reach: float = 0.5) -> list[dict]:
    """``n`` small boxes (20 x 20 x 40 mm) standing on the desk out of the arm's reach (farther than ``reach`` m
    from the base axis in front of it, or behind it), as plan-file obstacle dicts."""
    rng = np.random.default_rng(seed)
    out: list[dict] = []
    while len(out) < n:
        x, y = rng.uniform(DESK[0] - 0.1, DESK[1] + 0.15), rng.uniform(DESK[2] - 0.1, DESK[3] + 0.1)
        if np.hypot(x, y) < reach and x > -0.12:
            continue
        out.append({"name": f"box{len(out)}", "shape": "box", "size": [0.02, 0.02, 0.04],
                    "xyz": [round(float(x), 4), round(float(y), 4), 0.02]})
    return out


def _box_surface(rng, c, size, k: int) -> np.ndarray:
    """``k`` points on the five faces of a box (no bottom) of ``size`` standing at ``c`` (x, y, z of its base)."""
    sx, sy, sz = size
    areas = np.array([sx * sy, sy * sz, sy * sz, sx * sz, sx * sz])
    face = rng.choice(5, size=k, p=areas / areas.sum())
    u, v = rng.uniform(-0.5, 0.5, k), rng.uniform(-0.5, 0.5, k)
    p = np.zeros((k, 3))
    top, xm, xp, ym, yp = (face == i for i in range(5))
    p[top] = np.c_[u[top] * sx, v[top] * sy, np.full(top.sum(), sz)]
    for m, sign in ((xm, -1), (xp, 1)):
        p[m] = np.c_[np.full(m.sum(), sign * sx / 2), u[m] * sy, (v[m] + 0.5) * sz]
    for m, sign in ((ym, -1), (yp, 1)):
        p[m] = np.c_[u[m] * sx, np.full(m.sum(), sign * sy / 2), (v[m] + 0.5) * sz]
    return p + c


def _cylinder_surface(rng, c, radius: float, height: float, k: int) -> np.ndarray:
    """``k`` points on the side and top of an upright cylinder standing at ``c``."""
    side = rng.random(k) < (2 * np.pi * radius * height) / (2 * np.pi * radius * height + np.pi * radius**2)
    a = rng.uniform(0, 2 * np.pi, k)
    r = np.where(side, radius, radius * np.sqrt(rng.random(k)))
    z = np.where(side, rng.uniform(0, height, k), height)
    return np.c_[r * np.cos(a), r * np.sin(a), z] + c


def desk_cloud(n: int = 100_000, seed: int = 0) -> np.ndarray:
    """``n`` points (n, 3) m of the desk top (z just below 0, as a scan of the surface) and the clutter on it."""
    rng = np.random.default_rng(seed)
    n_desk = int(0.6 * n)
    desk = np.c_[rng.uniform(DESK[0], DESK[1], n_desk), rng.uniform(DESK[2], DESK[3], n_desk),
                 rng.uniform(-0.004, -0.0005, n_desk)]
    per = (n - n_desk) // len(CLUTTER)
    parts = [desk]
    for i, thing in enumerate(CLUTTER):
        k = per if i < len(CLUTTER) - 1 else n - n_desk - per * (len(CLUTTER) - 1)
        if thing[0] == "box":
            base_z = thing[6] if len(thing) > 6 else 0.0
            parts.append(_box_surface(rng, (thing[1], thing[2], base_z), thing[3:6], k))
        else:
            parts.append(_cylinder_surface(rng, (thing[1], thing[2], 0.0), thing[3], thing[4], k))
    return np.vstack(parts)


def _pick_place_plan(obstacles: list[dict], place: list[float], seed: int) -> dict:
    """obstacle.yaml's pick and place (the cube from (0.25, -0.15) to ``place``) among ``obstacles``, as a plan dict."""
    return {
        "robot": "roarm_m3_pro", "start": "home",
        "scene": {"table": {"shape": "box", "size": [0.80, 0.60, 0.02], "xyz": [0.15, 0.0, -0.01]}, "obstacles": obstacles},
        "objects": [{"name": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "xyz": [0.25, -0.15, 0.02], "mass": 0.03}],
        "tasks": [
            {"pick": {"object": "cube", "approach_height": 0.06, "pitch": {"deg": 90}, "gripper_open": 1.0, "gripper_closed": 0.6}},
            {"place": {"xyz": place, "approach_height": 0.06, "pitch": {"deg": 90}, "gripper_open": 1.0}},
            {"move": {"pose": "home", "gripper": "closed"}},
        ],
        "limits": {"velocity_scale": 0.6, "acceleration_scale": 0.6, "max_tcp_speed": 0.25, "gripper_time": 0.5},
        "planner": {"name": "RRTConnect", "time_budget": 2.0, "seed": seed, "singularity_margin": 0.02, "padding": 0.005},
    }


def tray_plan() -> dict:
    """A tray behind a tall wall: the cube is carried over a wall 0.20 m high and set down inside a tray (a 0.20 m
    square floor and four 30 mm rims) on the far side."""
    x, y, w, rim = 0.24, 0.17, 0.20, 0.03
    obstacles = [{"name": "wall", "shape": "box", "size": [0.20, 0.03, 0.20], "xyz": [0.26, 0.0, 0.10]},
                 {"name": "tray_floor", "shape": "box", "size": [w, w, 0.004], "xyz": [x, y, 0.002]}]
    for i, (dx, dy) in enumerate(((-1, 0), (1, 0), (0, -1), (0, 1))):
        size = [0.004, w, rim] if dx else [w, 0.004, rim]
        obstacles.append({"name": f"tray_rim{i}", "shape": "box", "size": size,
                          "xyz": [round(x + dx * w / 2, 4), round(y + dy * w / 2, 4), rim / 2]})
    return _pick_place_plan(obstacles, [x, y, 0.024], seed=3)


def posts_plan() -> dict:
    """Twelve posts: upright cylinders (15 mm radius, 0.14 m high) in two rows of six across the table between the
    pick and the place, the cube carried over or between them."""
    posts = [{"name": f"post{i}", "shape": "cylinder", "radius": 0.015, "length": 0.14,
              "xyz": [round(0.16 + 0.05 * (i % 6), 3), -0.04 if i < 6 else 0.04, 0.07]} for i in range(12)]
    return _pick_place_plan(posts, [0.25, 0.15, 0.02], seed=3)
