"""``roarmctl kin``: forward and inverse kinematics, Jacobian and dynamics from the command line.

Every command takes ``--deg`` (angles in and out in degrees) and ``--json`` (one JSON object on
stdout, nothing else); without ``--json`` a readable table is printed.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import typer

from roarmctl.cli import common

kin_app = typer.Typer(help="Kinematics and dynamics: fk, ik, jacobian, dynamics.", no_args_is_help=True)

DEG = typer.Option(False, "--deg", help="Angles in and out in degrees (default radians).")
JSON = typer.Option(False, "--json", help="Print one JSON object on stdout, nothing else.")


def register(app: typer.Typer) -> None:
    app.add_typer(kin_app, name="kin")


def _angles_out(values, deg: bool):
    arr = np.asarray(values, dtype=float)
    return np.degrees(arr) if deg else arr


def _table(title: str, rows: list[tuple[str, str]]) -> None:
    from rich.table import Table

    t = Table(title=title, show_header=False)
    t.add_column("quantity", style="bold")
    t.add_column("value")
    for k, v in rows:
        t.add_row(k, v)
    common.console().print(t)


def _fmt(a, digits: int = 6) -> str:
    return np.array2string(np.asarray(a, dtype=float), precision=digits, suppress_small=True, max_line_width=120)


@kin_app.command("fk")
def fk(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description."),
    q: list[str] = typer.Argument(..., help="Joint values (arm joints; the gripper may follow)."),
    link: Optional[str] = typer.Option(None, "--link", help="Link to report (default: the TCP)."),
    deg: bool = DEG,
    json_out: bool = JSON,
) -> None:
    """Forward kinematics: position (m), rotation (3x3) and roll-pitch-yaw of the TCP or a link."""
    from roarmctl.errors import InputError
    from roarmctl.robot.loader import load_robot
    from roarmctl.robot.model import rpy_from_matrix

    r = load_robot(robot)
    qv = r.full_q(common.parse_numbers(q, "joint value", deg))
    if link is not None and link not in r.kin.link_index:
        raise InputError(f"--link: '{link}' is not a link of {r.name}", f"links: {', '.join(r.link_names)}")
    t = r.kin.fk(qv, link)
    rpy = rpy_from_matrix(t[:3, :3])
    out = {"robot": r.name, "link": link or r.tcp_link, "q": _angles_out(qv, deg), "position": t[:3, 3],
           "rotation": t[:3, :3], "rpy": _angles_out(rpy, deg)}
    if json_out:
        common.print_json(out)
        return
    unit = "deg" if deg else "rad"
    _table(f"FK of {r.name} at {out['link']}", [
        (f"q ({unit})", _fmt(out["q"], 4)),
        ("position (m)", _fmt(t[:3, 3])),
        ("rotation", _fmt(t[:3, :3])),
        (f"rpy ({unit})", _fmt(out["rpy"], 4)),
    ])


@kin_app.command("jacobian")
def jacobian(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description."),
    q: list[str] = typer.Argument(..., help="Joint values (arm joints; the gripper may follow)."),
    deg: bool = DEG,
    json_out: bool = JSON,
) -> None:
    """Geometric Jacobian at the TCP (base frame), manipulability, singular values, ellipsoid, singularity."""
    from roarmctl.robot.loader import load_robot
    from roarmctl.robot.singularity import classify_singularity

    r = load_robot(robot)
    qv = r.full_q(common.parse_numbers(q, "joint value", deg))
    m = r.kin.manipulability(qv)
    out = {
        "robot": r.name,
        "q": _angles_out(qv, deg),
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
    _table(f"Jacobian of {r.name} at the TCP", [
        ("jacobian (6 x n)", _fmt(m.jacobian, 4)),
        ("manipulability", f"{m.manipulability:.6g}"),
        ("translational manipulability", f"{m.translational:.6g}"),
        ("singular values", _fmt(m.singular_values, 5)),
        ("ellipsoid radii (m/s per rad/s)", _fmt(m.ellipsoid_radii, 5)),
        ("ellipsoid axes (rows)", _fmt(m.ellipsoid_axes.T, 4)),
        ("singularity", str(out["singularity"])),
    ])
