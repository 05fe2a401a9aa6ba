"""``roarmctl kin``: forward and inverse kinematics, Jacobian and dynamics from the command line.

Every command takes ``--deg`` (angles in and out in degrees) and ``--json`` (one JSON object on
stdout, nothing else); without ``--json`` a readable table is printed.
"""

import math
from typing import TYPE_CHECKING, Any, overload

import typer

if TYPE_CHECKING:  # numpy itself is imported where a command runs (start-up time)
    from collections.abc import Iterable

    import numpy as np
    import numpy.typing as npt

    from roarmctl.robot.model import Robot

from roarmctl.cli import common
from roarmctl.errors import InputError, RoarmError, UnreachableError
from roarmctl.motion.options import PlannerConfig
from roarmctl.motion.rejection import judge

kin_app = typer.Typer(help="Kinematics and dynamics: fk, ik, jacobian, dynamics.", no_args_is_help=True)

DEG = typer.Option(False, "--deg", help="Angles in and out in degrees (default radians); prismatic joints stay in metres.")
JSON = typer.Option(False, "--json", help="Print one JSON object on stdout, nothing else.")
# Joint values may be negative: let '-0.5' through as an argument instead of an unknown option.
NUMBERS = {"ignore_unknown_options": True}
FRAME = typer.Option("world", "--frame", help="Positions in this frame of the robot: world (m, the plan's), or one the "
                                             "description names, e.g. firmware (RoArm: mm, origin at shoulder height, "
                                             "the firmware's and roarm-sdk's x/y/z of its own end point).")


def register(app: typer.Typer) -> None:
    """Add the ``kin`` command group to the app."""
    app.add_typer(kin_app, name="kin")


def _angles_out(values: "npt.ArrayLike", deg: bool) -> "np.ndarray":
    """Angles that are not joint values (pitch, roll, rpy): degrees when ``deg``."""
    import numpy as np

    arr = np.asarray(values, dtype=float)
    return np.degrees(arr) if deg else arr


def _looks_like_degrees(what: str, values: "Iterable[float | None]", deg: bool) -> None:
    """Warn when angles given without --deg are larger than a turn (2 pi rad): probably degrees."""
    big = [v for v in values if v is not None and math.isfinite(float(v)) and abs(float(v)) > 2 * math.pi]
    if big and not deg:
        common.warn(f"{what} {', '.join(f'{float(v):g}' for v in big)} look like degrees (more than 2 pi rad): read as "
                    f"radians; pass --deg if they are degrees")


def _joint_input(r: "Robot", values: list[str], deg: bool, what: str = "joint value") -> "np.ndarray":
    """The full configuration (rad, m) from joint values on the command line (arm joints, the gripper may
    follow; degrees for revolute joints with --deg, prismatic ones always in metres). Warns when values
    without --deg look like degrees, and when a value is outside its joint's limits."""
    raw = common.parse_numbers(values, what)
    cols = list(range(r.dof)) if raw.size == r.dof else list(r.arm_indices) if raw.size == r.arm_dof else []
    _looks_like_degrees(f"{what}s" if len(values) > 1 else what,
                        [v for v, c in zip(raw, cols, strict=False) if not r.prismatic[c]], deg)
    q = r.full_q(r.from_user(raw, deg))
    _outside_limits(r, q, deg, cols)
    return q


def _outside_limits(r: "Robot", q: "np.ndarray", deg: bool, cols: list[int]) -> None:
    """Warn for every given joint value outside its joint's limits, in the units it was given in."""
    out = [c for c in cols if not (r.lower[c] - 1e-9 <= q[c] <= r.upper[c] + 1e-9)]
    if not out:
        return
    shown = r.to_user(q, deg)
    lo, hi = r.to_user(r.lower, deg), r.to_user(r.upper, deg)
    common.warn("outside the joint limits (the arm cannot be there): " + "; ".join(
        f"{r.joint_names[c]} = {shown[c]:.4g} {r.joint_unit(c, deg=deg)} (limits [{lo[c]:.4g}, {hi[c]:.4g}])" for c in out))


def _units(r: "Robot", deg: bool, power: int = 0) -> list[str]:
    """Per actuated joint, the unit its values are shown in."""
    return [r.joint_unit(i, power, deg) for i in range(r.dof)]


def _unit_caption(r: "Robot", deg: bool) -> str:
    """'q1 = base, ...' plus which columns are in metres (prismatic joints), when any."""
    metres = [f"q{i + 1}" for i in range(r.dof) if r.prismatic[i]]
    return _joint_caption(r) + (f"; {', '.join(metres)} in m (prismatic)" if metres else "")


def _table(title: str, rows: list[tuple[str, str]]) -> None:
    from rich.table import Table

    t = Table(title=title, show_header=False)
    t.add_column("quantity", style="bold")
    t.add_column("value")
    for k, v in rows:
        t.add_row(k, v)
    common.console().print(t)


def _columns_table(title: str, columns: list[str], rows: "list[tuple[str, np.ndarray]]", digits: int = 4,
                   caption: str | None = None) -> None:
    """One row per quantity, one column per joint (fits 80 columns for up to 6 joints)."""
    import numpy as np
    from rich.table import Table

    t = Table(title=title, caption=caption)
    t.add_column("", style="bold")
    for c in columns:
        t.add_column(c, justify="right")
    for label, values in rows:
        t.add_row(label, *[_num(v, digits) for v in np.asarray(values, dtype=float).ravel()])
    common.console().print(t)


def _num(v: float, digits: int) -> str:
    text = f"{v:.{digits}f}"
    return "0" if float(text) == 0 else text  # no "-0.0000"


def _joint_caption(r: "Robot") -> str:
    return ", ".join(f"q{i + 1} = {common.shown(name)}" for i, name in enumerate(r.joint_names))


def _fmt(a: "npt.ArrayLike", digits: int = 6) -> str:
    import numpy as np

    return np.array2string(np.asarray(a, dtype=float), precision=digits, suppress_small=True, max_line_width=120)


@kin_app.command("fk", context_settings=NUMBERS)
def fk(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description."),
    q: list[str] = typer.Argument(..., help="Joint values (arm joints; the gripper may follow)."),
    link: str | None = typer.Option(None, "--link", help="Link to report (default: the TCP)."),
    frame: str = FRAME,
    deg: bool = DEG,
    json_out: bool = JSON,
) -> None:
    """Forward kinematics: position (m), rotation (3x3) and roll-pitch-yaw of the TCP or a link.

    With --frame firmware (RoArm) the position is the firmware's own end point in its frame (mm):
    what T:1051 x/y/z and roarm-sdk's pose_get() report; tcp_position is the TCP (the tcp_link) in that frame.
    """
    from roarmctl.robot.frames import device_point, get_frame, to_frame
    from roarmctl.robot.model import rpy_from_matrix

    r = common.load_robot(robot)
    fr = get_frame(r, frame)
    qv = _joint_input(r, q, deg)
    if link is not None and link not in r.kin.link_index:
        raise InputError(f"--link: '{link}' is not a link of {r.name}", f"links: {', '.join(r.link_names)}")
    t = r.kin.fk(qv, link)
    rpy = rpy_from_matrix(t[:3, :3])
    out: dict[str, Any] = {"robot": r.name, "link": link or r.tcp_link, "q": r.to_user(qv, deg), "q_units": _units(r, deg),
           "position": t[:3, 3], "rotation": t[:3, :3], "rpy": _angles_out(rpy, deg)}
    if frame != "world":
        point = t[:3, 3] if link is not None else device_point(r, fr, qv)
        out |= {"frame": frame, "unit": fr.unit, "position": to_frame(fr, point), "tcp_position": to_frame(fr, t[:3, 3]),
                "world_position": t[:3, 3]}
    if json_out:
        common.print_json(out)
        return
    unit = "deg" if deg else "rad"
    q_unit = unit if not r.prismatic.any() else f"{unit}; m for {', '.join(n for n, p in zip(r.joint_names, r.prismatic, strict=True) if p)}"
    rows = [(f"q ({q_unit})", _fmt(out["q"], 4))]
    if frame != "world":
        what = "end point" if link is None and fr.point_link else "position"
        rows += [(f"{what}, {frame} frame ({fr.unit})", _fmt(out["position"], 3)),
                 (f"{out['link']}, {frame} frame ({fr.unit})", _fmt(out["tcp_position"], 3))]
    rows += [
        ("position (m)" if frame == "world" else "position, world frame (m)", _fmt(t[:3, 3])),
        ("rotation (3x3, unitless)", _fmt(t[:3, :3])),
        (f"rpy ({unit})", _fmt(out["rpy"], 4)),
    ]
    _table(f"FK of {common.shown(r.name)} at {common.shown(out['link'])}", rows)


@kin_app.command("jacobian", context_settings=NUMBERS)
def jacobian(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description."),
    q: list[str] = typer.Argument(..., help="Joint values (arm joints; the gripper may follow)."),
    deg: bool = DEG,
    json_out: bool = JSON,
) -> None:
    """Geometric Jacobian at the TCP (base frame), manipulability, singular values, ellipsoid, singularity."""
    from roarmctl.robot.singularity import classify_singularity

    r = common.load_robot(robot)
    qv = _joint_input(r, q, deg)
    m = r.kin.manipulability(qv)
    out: dict[str, Any] = {
        "robot": r.name,
        "q": r.to_user(qv, deg),
        "q_units": _units(r, deg),
        "jacobian": m.jacobian,
        "manipulability": m.manipulability,
        "translational_manipulability": m.translational,
        "singular_values": m.singular_values,
        "ellipsoid_radii": m.ellipsoid_radii,
        "ellipsoid_axes": m.ellipsoid_axes.T,
        "singularity": classify_singularity(r, qv),
    }
    if json_out:
        common.print_json(out)
        return
    arm = [f"q{i + 1}" for i in r.arm_indices]
    k = len(m.ellipsoid_radii)
    _columns_table(f"Jacobian of {common.shown(r.name)} at the TCP (base frame)", arm, [
        ("vx (m/rad)", m.jacobian[0]), ("vy (m/rad)", m.jacobian[1]), ("vz (m/rad)", m.jacobian[2]),
        ("wx (rad/rad)", m.jacobian[3]), ("wy (rad/rad)", m.jacobian[4]), ("wz (rad/rad)", m.jacobian[5]),
    ], caption=_joint_caption(r) + " (m/rad: per rad of a revolute joint, m/m for a prismatic one)")
    sing = out["singularity"]
    sv = [f"{v:.4g}" for v in m.singular_values]
    _table(f"Manipulability of {common.shown(r.name)}", [
        (f"translational, 3x{len(arm)} Jv ((m/rad)^{k})", f"{m.translational:.6g}"),
        (f"full, 6x{len(arm)} J (mixed units)", f"{m.manipulability:.6g}"),
        ("singular values of J (mixed)", "\n".join(" ".join(sv[i:i + 3]) for i in range(0, len(sv), 3))),
        ("ellipsoid radii (m/s per rad/s)", " ".join(f"{v:.5g}" for v in m.ellipsoid_radii)),
        ("ellipsoid axes (base frame)", "\n".join(" ".join(f"{v:+.4f}" for v in a) for a in m.ellipsoid_axes.T)),
        ("singularity", sing if sing is not None else "none (no known singular configuration)"),
    ])


@overload
def _split_numbers(text: str, what: str, deg: bool) -> "np.ndarray": ...


@overload
def _split_numbers(text: None, what: str, deg: bool) -> None: ...


def _split_numbers(text: str | None, what: str, deg: bool) -> "np.ndarray | None":
    """'0 0.5 1.2' or '0,0.5,1.2' -> array (rad when ``deg``); None stays None."""
    if text is None:
        return None
    return common.parse_numbers([text], what, deg)


@kin_app.command("ik")
def ik(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description."),
    xyz: tuple[float, float, float] = typer.Option(..., "--xyz", help="Target TCP position X Y Z in metres (root frame), or in --frame's unit."),
    pitch: float | None = typer.Option(
        None, "--pitch",
        help="RoArm: angle of the approach axis (tool +x) below the horizontal, in the vertical plane through the "
             "base axis and the target (rad; deg with --deg): 0 points away from the base (home pose), pi/2 (90 deg) "
             "straight down. Left out: the pitch nearest to --ref's (else straight down), in 1 deg steps, at which "
             "the arm is within its limits, free of self-collision and clear of the singularity margin; printed."),
    roll: float | None = typer.Option(
        None, "--roll", help="RoArm: wrist-roll joint value, the turn of the tool about its approach axis (rad; deg with "
                             "--deg); default --ref's roll, else 0."),
    rpy: tuple[float, float, float] | None = typer.Option(
        None, "--rpy", help="Full target orientation as URDF roll pitch yaw, R = Rz Ry Rx (rad; deg with --deg). "
                            "Not with --pitch/--roll."),
    ref: str | None = typer.Option(
        None, "--ref", help="Reference configuration ('0 0 1.57 0 0' or comma-separated): solutions are sorted by "
                            "distance to it and its gripper value is kept."),
    all_solutions: bool = typer.Option(False, "--all", help="Print every solution (every branch) instead of the best one."),
    frame: str = FRAME,
    deg: bool = DEG,
    json_out: bool = JSON,
) -> None:
    """Inverse kinematics: joint vectors (gripper last) that put the TCP at --xyz, each checked by FK.

    Each solution's tool pitch is printed (RoArm), so a pitch found with --pitch left out can be
    written into a plan. With --frame firmware, --xyz is the firmware's end point in mm (T:1051 x/y/z).
    Unreachable targets exit with code 3 and say why: out_of_reach, joint_limit or orientation.
    """
    import numpy as np

    from roarmctl.robot.frames import device_point, from_frame, get_frame
    from roarmctl.robot.ik import (
        ORI_TOL,
        POS_TOL,
        check_solution,
        solve_ik_auto_pitch,
        solve_ik_frame,
        takes_pitch,
        tool_pitch,
    )

    r = common.load_robot(robot)
    fr = get_frame(r, frame)
    conv = (lambda v: float(np.radians(v))) if deg else float
    _looks_like_degrees("--pitch/--roll/--rpy", [pitch, roll, *(rpy or ())], deg)
    rpy_rad = None if rpy is None else np.array([conv(v) for v in rpy])
    q_ref = None if ref is None else _joint_input(r, [p for p in ref.replace(",", " ").split() if p], deg, "--ref value")
    target = from_frame(fr, np.array(xyz, dtype=float))
    is_roarm = takes_pitch(r)  # the IK takes a tool pitch: choose it when left out, print it
    auto = is_roarm and pitch is None and rpy is None
    xyz_arr = np.array(xyz, dtype=float)
    try:
        if auto:  # the pitch nearest to --ref's (else straight down) that is valid and clear of the margin
            from roarmctl.motion.collision import CollisionChecker
            from roarmctl.motion.scene import Scene

            checker = CollisionChecker(r, Scene([]), singularity_margin=PlannerConfig().singularity_margin)
            preferred = tool_pitch(r, q_ref, target) if q_ref is not None else float(np.pi / 2)
            sols, _ = solve_ik_auto_pitch(
                r, xyz_arr, preferred=preferred, roll=None if roll is None else conv(roll), q_ref=q_ref,
                all_solutions=all_solutions, accept=lambda qq: (v := judge(checker, qq[r.arm_indices])).valid or v.kind,
                solve=lambda p, **kw: solve_ik_frame(r, fr, p, **kw))
        else:
            sols = solve_ik_frame(r, fr, xyz_arr, pitch=None if pitch is None else conv(pitch),
                                  roll=None if roll is None else conv(roll), rpy=rpy_rad, q_ref=q_ref,
                                  all_solutions=all_solutions)
    except UnreachableError as exc:
        raise UnreachableError(f"unreachable ({exc.reason}): {exc.message}", exc.reason, exc.hint) from None
    checks = [check_solution(r, q, r.kin.fk(q)[:3, 3] + target - device_point(r, fr, q), rpy_rad) for q in sols]
    pitches = [tool_pitch(r, q, target) for q in sols] if is_roarm else None
    for q, c in zip(sols, checks, strict=True):  # the library checked already; a failure here is a bug, not an input error
        if c.position_error > POS_TOL or (c.orientation_error is not None and c.orientation_error > ORI_TOL):
            raise RoarmError(f"internal error: IK solution {np.round(q, 6).tolist()} misses the target by "
                             f"{c.position_error:.2e} m; please report this")
    out: dict[str, Any] = {
        "robot": r.name,
        "joint_names": r.joint_names,
        "target": {"position": list(xyz), "pitch": pitch, "roll": roll, "rpy": None if rpy is None else list(rpy)},
        "solutions": [r.to_user(q, deg) for q in sols],
        "units": _units(r, deg),
        "position_errors": [c.position_error for c in checks],
        "orientation_errors": [c.orientation_error for c in checks],
        "frame": frame,
        "world_target": target,
    }
    if pitches is not None:
        out["pitches"] = [float(_angles_out(p, deg)) for p in pitches]
    if json_out:
        common.print_json(out)
        return
    from rich.table import Table

    unit = "deg" if deg else "rad"
    where = (f"({xyz[0]:.4f}, {xyz[1]:.4f}, {xyz[2]:.4f}) m" if frame == "world" else
             f"({xyz[0]:.2f}, {xyz[1]:.2f}, {xyz[2]:.2f}) {fr.unit} in the {frame} frame")
    t = Table(title=f"IK of {common.shown(r.name)}: TCP at {where}, {len(sols)} solution(s), joints in {unit}",
              caption=_unit_caption(r, deg) + "; error: FK of the solution to the target")
    t.add_column("#")
    for i in range(r.dof):
        t.add_column(f"q{i + 1}", justify="right")
    if pitches is not None:
        t.add_column(f"pitch ({unit})", justify="right")
    t.add_column("error (m)", justify="right")
    digits = 2 if deg else 4  # 0.01 deg or 0.0001 rad: a UR10 row of 6 joints fits 80 columns
    for k, (q, c) in enumerate(zip(out["solutions"], checks, strict=True), 1):
        extra = [f"{out['pitches'][k - 1]:.2f}"] if pitches is not None else []
        t.add_row(str(k), *[f"{v:.{4 if p else digits}f}" for v, p in zip(q, r.prismatic, strict=True)], *extra,
                  f"{c.position_error:.1e}")
    common.console().print(t)
    if pitches is not None and pitch is None and rpy is None:
        common.console(stderr=True).print(f"pitch chosen (auto): {out['pitches'][0]:.2f} {unit} (pass --pitch to fix it)")


@kin_app.command("dynamics", context_settings=NUMBERS)
def dynamics(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description (with inertials)."),
    q_args: list[str] | None = typer.Argument(None, metavar="[Q]...", help="Joint positions, as for kin fk (or give --q)."),
    q: str | None = typer.Option(None, "--q", help="Joint positions, space- or comma-separated ('0 0.5 1.2 0 0'); arm joints, the gripper may follow."),
    qd: str | None = typer.Option(None, "--qd", help="Joint velocities (rad/s, or deg/s with --deg; m/s for prismatic joints); default 0."),
    qdd: str | None = typer.Option(None, "--qdd", help="Joint accelerations (rad/s^2, or deg/s^2 with --deg; m/s^2 for prismatic joints); default 0."),
    deg: bool = DEG,
    json_out: bool = JSON,
) -> None:
    """Inverse dynamics (recursive Newton-Euler, gravity 9.81 m/s^2 along -z): tau, mass matrix, gravity.

    tau = M(q) qdd + C(q, qd) qd + G(q), in N m (N for prismatic joints) for every actuated joint. --deg
    changes the units of --q/--qd/--qdd only; torques and the mass matrix stay SI (per radian).
    """
    import numpy as np

    from roarmctl.robot.dynamics import coriolis_vector, gravity_vector, inverse_dynamics, mass_matrix

    if (q is None) == (not q_args):
        raise InputError("give the joint positions once: after the robot (like kin fk) or as --q",
                         f"e.g. roarmctl kin dynamics {robot} 0 0.5 1.2 0 0")
    r = common.load_robot(robot)
    given = [p for p in q.replace(",", " ").split() if p] if q is not None else list(q_args or [])
    full = _joint_input(r, given, deg)
    n = len(given)
    qv = full if n == r.dof else full[r.arm_indices]
    qdv = r.from_user(_split_numbers(qd, "--qd", False), deg) if qd is not None else np.zeros(n)
    qddv = r.from_user(_split_numbers(qdd, "--qdd", False), deg) if qdd is not None else np.zeros(n)
    tau = inverse_dynamics(r, qv, qdv, qddv)
    out: dict[str, Any] = {
        "robot": r.name,
        "joint_names": r.joint_names,
        "q": r.to_user(full, deg),
        "q_units": _units(r, deg),
        "tau_units": [r.joint_unit(i, kind="effort") for i in range(r.dof)],
        "tau": tau,
        "mass_matrix": mass_matrix(r, full),
        "gravity": gravity_vector(r, full),
        "coriolis": coriolis_vector(r, full, qdv if qdv.size == r.dof else _pad(r, qdv)),
    }
    if json_out:
        common.print_json(out)
        return
    cols = [f"q{i + 1}" for i in range(r.dof)]
    mm = out["mass_matrix"]
    _columns_table(f"Inverse dynamics of {common.shown(r.name)}", cols, [
        (f"q ({'deg' if deg else 'rad'})", out["q"]),
        ("tau (N m)", tau),
        ("gravity G (N m)", out["gravity"]),
        ("C(q,qd) qd (N m)", out["coriolis"]),
    ], caption=_unit_caption(r, deg) + "; N m for a revolute joint, N for a prismatic one")
    _columns_table(f"Mass matrix M(q) of {common.shown(r.name)} (kg m^2: N m per rad/s^2)", cols,
                   [(f"row q{i + 1}", mm[i]) for i in range(r.dof)], digits=5)


def _pad(r: "Robot", v: "np.ndarray") -> "np.ndarray":
    import numpy as np

    out = np.zeros(r.dof)
    out[r.arm_indices] = v
    return out
