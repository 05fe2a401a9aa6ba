"""What a physics run measured, and its run file.

``measure`` turns a ``Recording`` into the report (plain JSON types):

* ``joints``: per joint, the tracking error against the plan at the same time (RMS and max, deg; m
  for prismatic joints), the peak torque of its servos (N m, the motor's ``n * stall * (duty - speed /
  no_load_speed)``), their stall torque, the share of stall and how long the loop's duty stayed at its
  limit (``saturated_s``; ``at_stall``: at the limit and nearly still for ``STALL_TIME`` or more), and
  the peak torque the plan needs there with the masses carried (``needed_nm``, RNEA of the planned
  motion; ``over_stall`` when it exceeds what the servos can give: the arm cannot follow the plan);
* ``tcp``: the TCP error (our FK of the simulated joints against the FK of the plan; RMS, max, mm),
  the lag that explains it best (``lag_ms``, and the RMS error against the plan delayed by it),
  the sag at rest (``rests``: for each stretch of at least ``REST_MIN`` s where the plan holds the arm
  still, the TCP error over its last ``REST_WINDOW`` s and how far below the plan, mm; ``sag_mm`` the
  largest; with sag compensation also ``compensated_mm``, how far the compensation raised the commanded TCP
  there: the sag the servos would have without it, ``compensated_mm`` at the top the largest) and the final
  error after settling;
* ``contacts``: the unintended contacts (``roarmctl.physics.contacts``);
* ``objects``: per picked object, whether it was lifted (while held it rose at least half as high as
  the plan carries it), where it came to rest against its place pose (the plan's: where the jaws put it at the
  release, turned with them), ``error_mm``/``error_deg``, and ``placed`` (within the tolerance);
* ``ok``: every picked object placed and no unintended contact.

``run_log`` is the run file: an execution log like ``execute``'s (``roarmctl.execlog/1``: every
command with its time, feedback lines as the firmware would print them at ``feedback_rate``) with a
``physics`` block (the report, tracks of the joints and objects, and the scene the run had, for viewers).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.execlog import ExecLog, trajectory_document
from roarmctl.device.fwmath import firmware_fk, position_to_rad
from roarmctl.device.protocol import M3_FEEDBACK_KEYS, M3_FIELDS, WireMap
from roarmctl.device.sag import offsets as sag_offsets
from roarmctl.device.schedule import sample
from roarmctl.errors import RoarmError
from roarmctl.motion.scene import Scene
from roarmctl.physics.mjcf import quat
from roarmctl.physics.run import Options, Recording
from roarmctl.physics.setup import Setup
from roarmctl.robot.bundle import make_bundle
from roarmctl.robot.dynamics import inverse_dynamics
from roarmctl.robot.loader import bundled_robots
from roarmctl.robot.model import Inertial, Robot

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory

REST_MIN = 0.3  # s: a rest shorter than this is not measured
REST_WINDOW = 0.1  # s at the end of a rest over which its error is averaged
STALL_TIME = 0.2  # s at the duty limit while nearly still: at stall
STILL = 0.05  # rad/s: "nearly still"
MAX_LAG = 0.2  # s: the longest lag looked for
LIFTED_SHARE = 0.5  # of the planned lift


def _r(x: float, n: int = 3) -> float:
    return round(float(x), n) + 0.0


def _plan_at(traj: Trajectory, t_physics: np.ndarray, scale: float) -> np.ndarray:

    return sample(traj, np.clip(t_physics * scale, 0.0, traj.duration))


def measure(traj: Trajectory, robot: Robot, setup: Setup, rec: Recording, options: Options) -> dict[str, Any]:
    """The report of one run (see the module doc)."""
    scale = options.speed_scale
    t_end = traj.duration / scale
    moving = rec.t <= t_end + 1e-9
    plan = _plan_at(traj, rec.t, scale)
    out: dict[str, Any] = {"joints": _joints(robot, setup, rec, plan, moving, _needed(traj, robot, setup))}
    out["tcp"] = _tcp(traj, robot, rec, plan, moving, scale, options.sag)
    out["contacts"] = [e.to_dict() for e in rec.episodes]
    out["objects"] = _objects(traj, robot, setup, rec, options)
    # a payload that names no object of the trajectory's scene: the run cannot say the pick worked (nothing was
    # there to lift), so it is not ok
    out["unmatched_payloads"] = [{"payload": k + 1, "grasp_s": _r(float(p["start"]), 4)}
                                 for k, (p, n) in enumerate(zip(traj.payloads, setup.objects_of_payloads)) if n is None]
    out["ok"] = bool(all(o["placed"] for o in out["objects"]) and not out["contacts"] and not out["unmatched_payloads"])
    sim = float(rec.t[-1]) if len(rec.t) else 0.0
    out["run"] = {"simulated_s": _r(sim), "wall_s": _r(rec.wall), "real_time_factor": _r(sim / rec.wall, 1) if rec.wall > 0 else None,
                  "cpu_s": _r(rec.cpu), "cpu_real_time_factor": _r(sim / rec.cpu, 1) if rec.cpu > 0 else None,
                  "timestep_s": rec.dt, "steps": int(len(rec.t)), "commands": len(rec.commands),
                  "rate": options.rate, "strategy": options.strategy, "speed_scale": scale, "sag_compensation": options.sag,
                  "tolerance_mm": _r(options.tolerance * 1e3, 1)}
    out["model"] = {"notes": list(setup.notes), "servos": _servos(robot, setup), "masses_kg": setup.world.doc.masses}
    return out


def _servos(robot: Robot, setup: Setup) -> list[dict[str, Any]]:
    bank = setup.actuation.bank
    return [{"joint": robot.joint_names[j], "servo": s.name, "count": int(c), "torque_limit": _r(lim),
             "field": f} for j, s, c, lim, f in zip(bank.joint, bank.spec, bank.count, bank.limit, setup.actuation.fields)]


def _needed(traj: Trajectory, robot: Robot, setup: Setup) -> np.ndarray | None:
    """Peak |torque| (dof,) N m the plan asks of each joint with the masses the physics carries (RNEA of the
    planned motion; a payload from its grasp to its release, with the mass the model gives its object), or
    None without inertias."""

    need = np.zeros(robot.dof)
    held = np.zeros(len(traj.times), dtype=bool)
    try:
        for p, name in zip(traj.payloads, setup.objects_of_payloads):
            k = (traj.times >= float(p["start"])) & (traj.times <= float(p["end"]))
            held |= k
            mass = setup.world.doc.masses.get(name, float(p["mass"])) if name is not None else float(p["mass"])
            scale = mass / float(p["mass"]) if float(p["mass"]) > 0 else 1.0
            load = {p["link"]: Inertial(mass, np.asarray(p["com"], dtype=float), np.asarray(p["inertia"], dtype=float) * scale)}
            if np.any(k):
                tau = inverse_dynamics(robot, traj.positions[k], traj.velocities[k], traj.accelerations[k], payload=load)
                need = np.maximum(need, np.max(np.abs(tau), axis=0))
        if np.any(~held):
            tau = inverse_dynamics(robot, traj.positions[~held], traj.velocities[~held], traj.accelerations[~held])
            need = np.maximum(need, np.max(np.abs(tau), axis=0))
    except RoarmError:
        return None
    return need


def _joints(robot: Robot, setup: Setup, rec: Recording, plan: np.ndarray, moving: np.ndarray,
            need: np.ndarray | None) -> list[dict[str, Any]]:
    bank = setup.actuation.bank
    err = rec.q[moving] - plan[moving]
    rows = []
    for j, name in enumerate(robot.joint_names):
        prismatic = next((jj.kind == "prismatic" for jj in robot.joints if jj.name == name), False)
        unit = 1e3 if prismatic else 180.0 / math.pi
        e = err[:, j]
        row: dict[str, Any] = {"name": name, "unit": "mm" if prismatic else "deg",
                               "rms": _r(np.sqrt(np.mean(e ** 2)) * unit) if len(e) else None,
                               "max": _r(np.max(np.abs(e)) * unit) if len(e) else None}
        chans = [c for c, jj in enumerate(bank.joint) if jj == j]
        if chans:
            tau = np.zeros(len(rec.t))
            stall = 0.0
            limit = 0.0
            for c in chans:
                spec = bank.spec[c]
                n = bank.count[c]
                tau += bank.sign[c] * n * spec.stall_torque * rec.duty[:, c] - n * spec.damping * rec.qd[:, j]
                stall += n * spec.stall_torque
                limit = max(limit, bank.limit[c])
            saturated = np.any(np.abs(rec.duty[:, chans]) >= np.array([bank.limit[c] for c in chans]) - 1e-9, axis=1)
            still = np.abs(rec.qd[:, j]) < STILL
            row.update({"peak_torque_nm": _r(np.max(np.abs(tau))), "stall_nm": _r(stall),
                        "peak_share_of_stall": _r(np.max(np.abs(tau)) / stall), "torque_limit": _r(limit),
                        "saturated_s": _r(np.count_nonzero(saturated) * rec.dt),
                        "at_stall": bool(_longest(saturated & still) * rec.dt >= STALL_TIME)})
            if need is not None:
                row.update({"needed_nm": _r(need[j]), "needed_share_of_stall": _r(need[j] / stall),
                            "over_stall": bool(need[j] > stall * limit)})
        rows.append(row)
    return rows


def _longest(mask: np.ndarray) -> int:
    """Length of the longest run of True in ``mask``."""
    best = run = 0
    for v in mask:
        run = run + 1 if v else 0
        best = max(best, run)
    return best


def _tcp(traj: Trajectory, robot: Robot, rec: Recording, plan: np.ndarray, moving: np.ndarray, scale: float,
         sag: bool) -> dict[str, Any]:
    stride = max(1, int(round(0.01 / rec.dt)))  # the TCP error every 10 ms
    idx = np.flatnonzero(moving)[::stride]
    sim = robot.kin.fk(rec.q[idx])[:, :3, 3]
    ref = robot.kin.fk(plan[idx])[:, :3, 3]
    e = np.linalg.norm(sim - ref, axis=1) * 1e3
    rests: list[dict[str, Any]] = []
    for s in _rests(traj, robot):
        a, b = s[0] / scale, s[1] / scale
        k = (rec.t >= b - REST_WINDOW) & (rec.t <= b)
        if not np.any(k):
            continue
        d = (robot.kin.fk(rec.q[k])[:, :3, 3] - robot.kin.fk(plan[k])[:, :3, 3]).mean(axis=0)
        rests.append({"start_s": _r(a), "end_s": _r(b), "label": s[2], "error_mm": _r(float(np.linalg.norm(d)) * 1e3, 2),
                      "below_mm": _r(-d[2] * 1e3, 2)})
        if sag and robot.wire:  # what the schedule's offsets (the same function) did to the commanded TCP there
            tm = s[1] - REST_WINDOW / 2
            q = sample(traj, tm)[None, :]
            lift = robot.kin.fk(q + sag_offsets(robot, traj, [tm], q))[0, :3, 3] - robot.kin.fk(q)[0, :3, 3]
            rests[-1]["compensated_mm"] = _r(float(np.linalg.norm(lift)) * 1e3, 2)
    final = float(np.linalg.norm(robot.kin.fk(rec.q[-1])[:3, 3] - robot.kin.fk(traj.positions[-1])[:3, 3]) * 1e3)
    lag, lagged = _lag(traj, robot, rec.t[idx], sim, scale)
    return {"rms_mm": _r(np.sqrt(np.mean(e ** 2)), 2) if len(e) else None, "max_mm": _r(np.max(e), 2) if len(e) else None,
            "lag_ms": lag, "rms_after_lag_mm": lagged,
            "sag_mm": max((float(r["error_mm"]) for r in rests), default=None), "final_mm": _r(final, 2), "rests": rests,
            "compensated_mm": max((float(r["compensated_mm"]) for r in rests if "compensated_mm" in r), default=None)}


def _lag(traj: Trajectory, robot: Robot, t: np.ndarray, sim: np.ndarray,
         scale: float) -> tuple[float | None, float | None]:
    """The time (ms, 0-``MAX_LAG``) by which the simulated TCP follows the plan best, and the RMS error (mm)
    against the plan delayed by it: how much of the tracking error is lag along the path."""
    if len(t) < 2:
        return None, None
    shifts = np.arange(0.0, MAX_LAG + 1e-9, 0.002)
    rms = [float(np.sqrt(np.mean(np.sum((sim - robot.kin.fk(_plan_at(traj, t - d, scale))[:, :3, 3]) ** 2, axis=1))))
           for d in shifts]
    k = int(np.argmin(rms))
    return _r(shifts[k] * 1e3, 1), _r(rms[k] * 1e3, 2)


def _rests(traj: Trajectory, robot: Robot) -> list[tuple[float, float, str]]:
    """(start, end, label) of the trajectory's segments (s) in which no arm joint moves, at least ``REST_MIN`` long."""
    arm = robot.arm_indices
    out = []
    for s in traj.segments:
        if s.end - s.start < REST_MIN:
            continue
        k = (traj.times >= s.start - 1e-9) & (traj.times <= s.end + 1e-9)
        v = traj.velocities[k][:, arm]
        if v.size and float(np.max(np.abs(v))) < 1e-6:
            out.append((float(s.start), float(s.end), s.label))
    return out


def _objects(traj: Trajectory, robot: Robot, setup: Setup, rec: Recording, options: Options) -> list[dict[str, Any]]:

    scene = Scene.from_dict(traj.scene)
    scale = options.speed_scale
    rows = []
    for p, name in zip(traj.payloads, setup.objects_of_payloads):
        if name is None or name not in rec.objects:
            continue
        start = scene[name].pose
        tg, tr = float(p["start"]), float(p["end"])
        link = p["link"]
        t_g = robot.kin.fk(robot.full_q(sample(traj, tg)), link)
        t_r = robot.kin.fk(robot.full_q(sample(traj, tr)), link)
        planned = t_r @ np.linalg.inv(t_g) @ start
        held = (traj.times >= tg) & (traj.times <= tr)  # the planned object, carried rigidly: its highest rise
        rel = np.linalg.inv(t_g) @ start
        tl = robot.kin.fk(traj.positions[held], link)
        planned_lift = float(np.max(tl[:, 2, :3] @ rel[:3, 3] + tl[:, 2, 3]) - start[2, 3]) if np.any(held) else 0.0
        xs, qs = rec.objects[name]
        k = (rec.track_t >= tg / scale) & (rec.track_t <= tr / scale)
        rise = float(np.max(xs[k, 2]) - start[2, 3]) if np.any(k) else 0.0
        end_xyz, end_q = xs[-1], qs[-1]
        err = float(np.linalg.norm(end_xyz - planned[:3, 3]))
        rows.append({"name": name, "lifted": bool(rise >= LIFTED_SHARE * planned_lift), "lift_mm": _r(rise * 1e3, 1),
                     "planned_lift_mm": _r(planned_lift * 1e3, 1), "placed": bool(err <= options.tolerance),
                     "error_mm": _r(err * 1e3, 2), "error_deg": _r(_angle(end_q, planned[:3, :3]), 2),
                     "final_xyz_m": [_r(v, 4) for v in end_xyz], "place_xyz_m": [_r(v, 4) for v in planned[:3, 3]],
                     "mass_kg": setup.world.doc.masses.get(name)})
    return rows


def _angle(quat_wxyz: Sequence[float], rot: np.ndarray) -> float:
    """Angle (deg) between the rotation of a unit quaternion (w, x, y, z) and a rotation matrix."""

    q2 = np.array(quat(rot))
    d = abs(float(np.dot(np.asarray(quat_wxyz, dtype=float), q2)))
    return math.degrees(2.0 * math.acos(min(1.0, d)))


# ----------------------------------------------------------------------------- the run file
def run_log(traj: Trajectory, robot: Robot, setup: Setup, rec: Recording, options: Options, report: dict[str, Any],
            source: str | None = None) -> dict[str, Any]:
    """The run file: ``roarmctl.execlog/1`` (as ``execute`` writes it) plus ``physics``."""
    sent = [{"t": _r(t, 6), "cmd": cmd, "tick": k, "lateness": 0.0} for t, cmd, k in rec.commands]
    received = _feedback(robot, setup, rec, options)
    tr = report["tcp"]
    tracking = _tracking(traj, robot, rec, options)
    stride = max(1, int(round(1.0 / (options.track_rate * rec.dt))))
    tracks = {"t": [_r(t, 4) for t in rec.t[::stride]],
              "q": [[_r(v, 6) for v in row] for row in rec.q[::stride]],
              "objects": {n: {"t": [_r(t, 4) for t in rec.track_t], "xyz": [[_r(v, 5) for v in p] for p in xs],
                              "quat": [[_r(v, 6) for v in q] for q in qs]} for n, (xs, qs) in rec.objects.items()}}
    log = ExecLog(
        robot=robot.name, port="physics", firmware="physics", speed_scale=options.speed_scale, t0_monotonic=0.0,
        robot_description=_description(traj, source),
        details={
            "strategy": options.strategy, "rate": options.rate, "duration": _r(traj.duration / options.speed_scale, 6),
            "summary": {"outcome": "completed" if report["ok"] else "failed",
                        "message": "" if report["ok"] else _failure(report),
                        "commands": sum(1 for _t, c, _k in rec.commands if c.get("T") == 102),
                        "lateness_ms": {"p50": 0.0, "p99": 0.0, "max": 0.0},
                        "tracking_mm": {"rms": tr["rms_mm"], "max": tr["max_mm"], "samples": len(tracking)},
                        "final_error_mm": tr["final_mm"]},
            "notes": list(setup.notes),
            "final_pose": {"world_m": [_r(v, 6) for v in robot.kin.fk(rec.q[-1])[:3, 3]]},
            "tracking": tracking,
            "physics": report | {"tracks": tracks, "scene": traj.scene}},
        trajectory=trajectory_document(traj), sent=sent, received=received).to_dict()
    json.dumps(log, allow_nan=False)  # a NaN in a report is a bug: fail here, not in the reader
    return log


def _description(traj: Trajectory, source: str | None) -> dict[str, Any] | None:
    """The run file's ``robot_description`` (``roarmctl.robot.bundle``): the trajectory's, or the bundle of the
    description ``source`` that the run used instead (``simulate --robot``), so that ``export`` reads the run
    by itself; None for a bundled robot."""
    if source is not None:
        return None if source in bundled_robots() else make_bundle(source)
    return getattr(traj, "robot_description", None)


def _failure(report: dict[str, Any]) -> str:
    bad = [o["name"] for o in report["objects"] if not o["placed"]]
    parts = []
    if bad:
        parts.append("not placed within tolerance: " + ", ".join(bad))
    if report["contacts"]:
        parts.append(f"{len(report['contacts'])} unintended contact(s)")
    for u in report.get("unmatched_payloads", []):
        parts.append(f"payload {u['payload']} (grasp at {u['grasp_s']:.2f} s) picks no object of the trajectory's scene")
    return "; ".join(parts)


def _tracking(traj: Trajectory, robot: Robot, rec: Recording, options: Options) -> list[dict[str, float]]:
    """TCP error samples at the feedback rate during the motion: {"t", "error_m"} as execute logs them."""
    step = max(1, int(round(1.0 / (options.feedback_rate * rec.dt))))
    t_end = traj.duration / options.speed_scale
    idx = np.flatnonzero(rec.t <= t_end + 1e-9)[::step]
    plan = _plan_at(traj, rec.t[idx], options.speed_scale)
    e = np.linalg.norm(robot.kin.fk(rec.q[idx])[:, :3, 3] - robot.kin.fk(plan)[:, :3, 3], axis=1)
    return [{"t": _r(t, 6), "error_m": _r(v, 6)} for t, v in zip(rec.t[idx], e)]


def _feedback(robot: Robot, setup: Setup, rec: Recording, options: Options) -> list[dict[str, Any]]:
    """T:1051 lines at ``feedback_rate`` as the firmware prints them from its servo reads (whole steps,
    ``calculateRadByFeedback``), with our FK's TCP in the world frame. Only for a streamed RoArm."""
    act = setup.actuation
    if not act.streamed:
        return []

    wm = WireMap(robot)
    keys = dict(zip(M3_FIELDS, M3_FEEDBACK_KEYS))
    if wm.model == "m2":
        keys = dict(zip(("base", "shoulder", "elbow", "hand"), ("b", "s", "e", "t")))
    step = max(1, int(round(1.0 / (options.feedback_rate * rec.dt))))
    out = []
    fields = [str(f) for f in act.fields]  # a streamed RoArm: every channel has its field
    for k in range(0, len(rec.t), step):
        steps = act.bank.steps(rec.q[k])
        rad = {f: position_to_rad(i, float(round(p))) for f, i, p in zip(fields, act.firmware_index, steps)}
        obj: dict[str, Any] = {"T": 1051}
        if wm.model == "m3":
            x, y, z, tit = firmware_fk(rad["base"], rad["shoulder"], rad["elbow"], rad["wrist"])
            obj |= {"x": _r(x, 2), "y": _r(y, 2), "z": _r(z, 2), "tit": _r(tit, 6)}
        obj |= {keys[f]: _r(v, 6) for f, v in rad.items()}
        loads = {f: int(round(1000 * d)) for f, d in zip(fields, rec.duty[k])}
        obj |= ({f"t{keys[f].upper()}": v for f, v in loads.items()} if wm.model == "m3"
                else {f"tor{keys[f].upper()}": v for f, v in loads.items()})
        q = wm.from_wire(rad)
        out.append({"t": _r(rec.t[k], 6), "line": json.dumps(obj, separators=(",", ":")), "feedback": obj,
                    "tcp_world_m": [_r(v, 6) for v in robot.kin.fk(q)[:3, 3]]})
    return out
