"""Hand-built pick-and-place trajectories for the visualisation tests and benchmark.

They stand in for ``roarmctl plan`` output: free motions are joint-space splines through a few
configurations, Cartesian segments are straight TCP lines solved by a small damped least-squares IK
(gripper pointing down), times follow quintic smoothstep profiles (zero velocity at each end).
Velocities and accelerations are the analytic derivatives of the joint splines for free motions and
central differences for Cartesian ones, which is accurate enough for drawing.
"""

from __future__ import annotations

import numpy as np

from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.robot.loader import load_robot

RATE = 100.0
DOWN = np.array([0.0, 0.0, -1.0])

SCENE = {
    "items": [
        {"name": "table", "role": "table", "shape": "box", "size": [0.8, 0.6, 0.02], "xyz": [0.15, 0.0, -0.01], "rpy": [0, 0, 0]},
        {"name": "cube", "role": "object", "shape": "box", "size": [0.04, 0.04, 0.04], "xyz": [0.25, -0.15, 0.02], "rpy": [0, 0, 0]},
        {"name": "divider", "role": "obstacle", "shape": "box", "size": [0.04, 0.10, 0.15], "xyz": [0.28, 0.0, 0.075], "rpy": [0, 0, 0]},
    ]
}
PICK = np.array([0.25, -0.15, 0.02])
PLACE = np.array([0.25, 0.15, 0.02])


def ik_down(robot, target: np.ndarray, q0: np.ndarray, iters: int = 100) -> np.ndarray:
    """Full q reaching ``target`` (m) with the TCP approach axis (its x axis) pointing down.

    Damped least squares on base, shoulder, elbow and wrist; roll and gripper are kept from ``q0``.
    """
    q = np.array(q0, dtype=float)
    idx = [0, 1, 2, 3]
    for _ in range(iters):
        t = robot.kin.fk(q)
        err = np.concatenate([target - t[:3, 3], DOWN - t[:3, 0]])
        if np.linalg.norm(err[:3]) < 1e-9 and np.linalg.norm(err[3:]) < 1e-5:
            break
        jac = robot.kin.jacobian(q)
        jp = jac[:3, idx]
        # d(x axis)/dq = omega x x_axis
        jr = np.cross(jac[3:, idx].T, t[:3, 0]).T
        a = np.vstack([jp, jr])
        dq = a.T @ np.linalg.solve(a @ a.T + 1e-6 * np.eye(6), err)
        q[idx] += dq
    return q


def _smooth(s: np.ndarray):
    """Quintic smoothstep and its first two derivatives w.r.t. s."""
    return 10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3


GEOM = 120  # samples of each geometric path in its parameter u in [0, 1]


def _free_path(qs: list[np.ndarray]):
    """Joint-space path through ``qs``: q(u), dq/du, d2q/du2 on GEOM + 1 samples (C2 spline)."""
    from scipy.interpolate import CubicSpline

    u = np.linspace(0.0, 1.0, GEOM + 1)
    spline = CubicSpline(np.linspace(0.0, 1.0, len(qs)), np.array(qs), bc_type="natural")
    return u, spline(u), spline(u, 1), spline(u, 2)


def _line_path(robot, q_start: np.ndarray, end: np.ndarray):
    """Straight TCP line from FK(q_start) to ``end`` (gripper down), IK per sample; derivatives numeric."""
    u = np.linspace(0.0, 1.0, GEOM + 1)
    start = robot.kin.fk(q_start)[:3, 3]
    q, out = q_start, [q_start]
    for ui in u[1:]:
        q = ik_down(robot, start + ui * (end - start), q)
        out.append(q)
    p = np.array(out)
    dp = np.gradient(p, u, axis=0, edge_order=2)
    return u, p, dp, np.gradient(dp, u, axis=0, edge_order=2)


def _timed(robot, path, vmax, amax, vtcp, fill: float = 0.9):
    """Sample ``path`` at RATE with a smoothstep u(t); duration so that peaks stay within ``fill`` of the limits."""
    from scipy.interpolate import CubicSpline

    u, p, dp, ddp = path
    _s, ds, dds = _smooth(u)
    v1 = dp * ds[:, None]  # at duration 1
    a1 = ddp * (ds**2)[:, None] + dp * dds[:, None]
    tcp1 = np.linalg.norm(np.einsum("nij,nj->ni", robot.kin.jacobian(p)[:, :3, :], v1[:, robot.arm_indices]), axis=1)
    ratio_v = max(np.max(np.abs(v1) / vmax), np.max(tcp1) / vtcp)
    ratio_a = np.max(np.abs(a1) / amax)
    duration = max(ratio_v / fill, np.sqrt(ratio_a / fill), 0.3)
    n = int(np.ceil(duration * RATE))
    duration = n / RATE
    tau = np.arange(1, n + 1) / n
    st, dst, ddst = _smooth(tau)
    fp, fdp, fddp = (CubicSpline(u, x) for x in (p, dp, ddp))
    pos, d1, d2 = fp(st), fdp(st), fddp(st)
    vel = d1 * (dst / duration)[:, None]
    acc = d2 * ((dst / duration) ** 2)[:, None] + d1 * (ddst / duration**2)[:, None]
    return pos, vel, acc


def pick_place_trajectory(robot_name: str = "roarm_m3_pro", velocity_scale: float = 0.5,
                          acceleration_scale: float = 0.5, max_tcp_speed: float | None = 0.25,
                          min_singular_value: float | None = 0.02) -> Trajectory:
    """A RoArm pick (cube at PICK) and place (at PLACE, over the divider) with grasp and release events."""
    robot = load_robot(robot_name)
    home = robot.full_q(robot.named_poses["ready"])
    g_open, g_hold, g_closed = 1.2, 0.55, robot.gripper.closed
    hover = 0.10
    above_pick = ik_down(robot, PICK + [0, 0, hover], home)
    above_pick[-1] = g_open
    via = np.array([0.0, 0.0, 1.2, 1.0, 0.0, 0.0])  # leaning back over the divider, gripper tilted 25 deg
    above_place = ik_down(robot, PLACE + [0, 0, hover], above_pick)

    vmax = robot.velocity_limits * velocity_scale
    amax = robot.acceleration_limits * acceleration_scale
    vtcp = max_tcp_speed or np.inf
    times, P, V, A = [0.0], [home], [np.zeros(robot.dof)], [np.zeros(robot.dof)]
    segments, events = [], []

    def add(path, kind: str, label: str) -> None:
        p, v, a = _timed(robot, path, vmax, amax, vtcp)
        t0 = times[-1]
        times.extend(t0 + np.arange(1, len(p) + 1) / RATE)
        P.extend(p), V.extend(v), A.extend(a)
        segments.append(Segment(t0, times[-1], kind, label))

    def grip(value: float) -> list[np.ndarray]:
        q = P[-1].copy()
        q[-1] = value
        return [P[-1], q]

    via_out = via.copy()
    via_out[-1] = g_open
    add(_free_path([home, via_out, above_pick]), "free", "approach cube")
    add(_line_path(robot, P[-1], PICK), "cartesian", "descend to cube")
    events.append(Event(times[-1], "grasp", "pick cube", list(PICK)))
    add(_free_path(grip(g_hold)), "gripper", "close gripper")
    add(_line_path(robot, P[-1], PICK + [0, 0, hover]), "cartesian", "lift cube")
    q_lift = P[-1].copy()
    via_carry = via.copy()
    via_carry[-1] = above_place[-1] = q_lift[-1]
    add(_free_path([q_lift, via_carry, above_place]), "free", "carry over divider")
    add(_line_path(robot, P[-1], PLACE), "cartesian", "lower cube")
    events.append(Event(times[-1], "release", "place cube", list(PLACE)))
    add(_free_path(grip(g_open)), "gripper", "open gripper")
    add(_line_path(robot, P[-1], PLACE + [0, 0, hover]), "cartesian", "retreat")
    q_end = home.copy()
    q_end[-1] = g_closed
    add(_free_path([P[-1], via_out, q_end]), "free", "return")

    limits = {
        "velocity": robot.velocity_limits.tolist(),
        "acceleration": robot.acceleration_limits.tolist(),
        "velocity_scale": velocity_scale,
        "acceleration_scale": acceleration_scale,
        "max_tcp_speed": max_tcp_speed,
    }
    return Trajectory(
        robot=robot_name,
        joint_names=list(robot.joint_names),
        times=np.array(times),
        positions=np.array(P),
        velocities=np.array(V),
        accelerations=np.array(A),
        events=events,
        segments=segments,
        limits=limits,
        singularity_margin=None if min_singular_value is None else {"min_singular_value": min_singular_value},
        scene=SCENE,
    )


def planar_trajectory() -> Trajectory:
    """A bare two-link trajectory: no scene, no events, no limits block (the robot's limits apply)."""
    robot = load_robot("planar_2r")
    p, v, a = _timed(robot, _free_path([np.array([0.3, 1.2]), np.array([1.2, -0.6])]),
                     robot.velocity_limits, robot.acceleration_limits, np.inf)
    z = np.zeros((1, 2))
    return Trajectory("planar_2r", list(robot.joint_names), np.arange(len(p) + 1) / RATE,
                      np.vstack([[0.3, 1.2], p]), np.vstack([z, v]), np.vstack([z, a]))
