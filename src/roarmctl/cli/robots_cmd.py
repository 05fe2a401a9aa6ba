"""``roarmctl robots`` (the bundled robots) and ``roarmctl robots show ARM`` (one robot, where each value came from)."""

from typing import Any

import typer

from roarmctl.cli import common

robots_app = typer.Typer(invoke_without_command=True, no_args_is_help=False, rich_markup_mode=None,
                         help="List the bundled robots; 'robots show ARM' shows one robot and where each value came from.")


def register(app: typer.Typer) -> None:
    """Add ``robots`` and ``robots show`` to ``app``."""
    app.add_typer(robots_app, name="robots")


@robots_app.callback()
def robots(ctx: typer.Context, json_out: bool = typer.Option(False, "--json", help="Print one JSON object.")) -> None:
    """List the bundled robots (name, joints, source)."""
    if ctx.invoked_subcommand is not None:
        return
    from roarmctl.robot.loader import bundled_robots, load_robot

    rows: list[dict[str, Any]] = []
    for name in bundled_robots():
        r = load_robot(name)
        rows.append({"name": name, "joints": r.joint_names, "dof": r.dof, "source": r.source, "description": r.description})
    if json_out:
        common.print_json({"robots": rows})
        return
    from rich.table import Table

    table = Table(title="Bundled robots")
    for col in ("name", "dof", "joints", "source"):
        table.add_column(col)
    for row in rows:
        table.add_row(common.shown(row["name"]), str(row["dof"]), common.shown(", ".join(row["joints"])), common.shown(row["source"]))
    common.console().print(table)


@robots_app.command("show")
def show(
    arm: str = typer.Argument(..., help="A bundled robot's name or a description (.yaml sidecar, .urdf, .xacro).",
                              show_default=False),
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """One robot: joints with types, limits and units, TCP and tool, gripper, poses, groups, allowed collision
    pairs, meshes, and where each value came from (URDF, SRDF, joint_limits.yaml, sidecar, roarmctl default)."""
    from roarmctl.robot.provenance import summary

    info = summary(arm)
    if json_out:
        common.print_json(info)
        return
    from rich.table import Table

    out = common.console()
    table = Table(title=f"{common.shown(info['name'])} ({common.shown(info['sidecar'] or info['spec'])})")
    for col in ("joint", "type", "range", "velocity", "acceleration", "effort"):
        table.add_column(col)
    for j in info["joints"]:
        effort = "-" if j["effort"] is None else f"{j['effort']:.4g} {j['effort_unit']}"
        table.add_row(common.shown(j["name"]), j["type"], f"{j['lower']:.4g} .. {j['upper']:.4g} {j['unit']}\n[{j['position_source']}]",
                      f"{j['velocity']:.4g} {j['velocity_unit']}\n[{j['velocity_source']}]",
                      f"{j['acceleration']:.4g} {j['acceleration_unit']}\n[{j['acceleration_source']}]",
                      f"{effort}\n[{j['effort_source']}]")
    out.print(table, markup=False)
    tcp = info["tcp"]
    tool = "" if tcp["tool"] is None else f", tool offset xyz {tcp['tool']['xyz']} m rpy {tcp['tool']['rpy']} rad [sidecar]"
    lines = [f"TCP: {tcp['link']} [{tcp['source']}]{tool}"]
    g = info["gripper"]
    lines.append("gripper: none" if g is None else f"gripper: {g['joint']} open {g['open']:g} closed {g['closed']:g} [{g['source']}]")
    poses = info["named_poses"]
    lines.append("named poses: " + (", ".join(f"{n} [{p['source']}]" for n, p in poses.items()) or "none"))
    if info["held_joints"]:
        lines.append("held still: " + ", ".join(f"{n} at {v:g}" for n, v in info["held_joints"].items()))
    if info["groups"]:
        lines.append("groups: " + ", ".join(f"{k} {v} [sidecar]" for k, v in info["groups"].items()))
    by_source: dict[str, int] = {}
    for pair in info["allowed_collisions"]:
        by_source[pair["source"]] = by_source.get(pair["source"], 0) + 1
    lines.append(f"collision pairs disabled: {len(info['allowed_collisions'])} ("
                 + ", ".join(f"{n} {s}" for s, n in by_source.items()) + ")")
    m = info["meshes"]
    lines.append(f"collision shapes: {m['collision_shapes']} ({m['collision']} meshes); visual elements: {m['visual_elements']}")
    lines += [f"note: {n}" for n in info["notes"]]
    for line in lines:
        out.print(line, markup=False, highlight=False)
