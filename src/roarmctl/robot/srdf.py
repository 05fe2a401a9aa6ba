"""MoveIt's SRDF and joint_limits.yaml, turned into sidecar fields.

SRDF (``srdf: file.srdf`` in the sidecar; a ``.xacro`` SRDF is expanded like the URDF, with the same
``xacro_args`` and ``packages``):
- ``disable_collisions`` -> ``allowed_collisions`` pairs;
- the arm group (``arm_group``, else the group with a ``chain``) -> ``tcp_link`` (the chain's tip)
  and its ``group_state``s -> ``named_poses`` (every arm joint must have a value);
- ``passive_joint``: joints that no motor drives (MoveIt Setup Assistant writes one for every mimic
  finger joint); a passive joint that is not a mimic joint is held still, like a movable joint the
  sidecar's ``joints`` does not list;
- the gripper group: ``gripper_group`` when the sidecar names it, else the first of the end effectors'
  groups, a group named ``gripper`` or ``hand`` that drives exactly one joint (mimic and passive joints
  follow, they are not counted) -> ``gripper.joint``, and its ``group_state``s named ``open`` and
  ``close``/``closed`` (any case) -> ``gripper.open`` / ``gripper.closed``. A sidecar ``gripper:``
  wins over all of it (the SRDF's group is then only used to sort its states);
- ``virtual_joint`` of type fixed is accepted (the URDF root is fixed to the world).
Other groups' states and unknown elements are left out with a note (``notes``), and so is what srdfdom
skips (its ``model.cpp`` logs and goes on): an element inside a ``<group>`` other than joint, link, chain and
group (``<passive_joint>`` written there), a joint or link the URDF does not have (in a group, a chain, a
``passive_joint``, a ``disable_collisions`` pair, a ``group_state``). Elements whose meaning would change the
robot (floating virtual joints, ``disable_default_collisions``) are errors.

joint_limits.yaml (``joint_limits: file.yaml``): per joint ``has_velocity_limits`` /
``max_velocity``, ``has_acceleration_limits`` / ``max_acceleration``, ``has_position_limits`` /
``min_position`` / ``max_position``; a limit whose ``has_*`` is false is not used (the URDF's or the
sidecar's applies). ``default_velocity_scaling_factor`` / ``default_acceleration_scaling_factor``
are MoveIt's per-request defaults: read and checked, not limits (the plan file's
``velocity_scale`` plays that role). Jerk limits are refused when switched on. Entries for joints
that roarmctl does not drive (mimic fingers) are read and checked but not used.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from roarmctl.errors import DescriptionError, describe_value
from roarmctl.fileio import Roots, read_text
from roarmctl.robot.xacro_input import expand
from roarmctl.validation import check_markup, load_yaml

SRDF_BYTES = 16 * 1024 * 1024  # an SRDF may have (MoveIt's of published arms: < 100 KiB)
_KNOWN = {"group", "group_state", "disable_collisions", "end_effector", "virtual_joint", "disable_default_collisions",
          "passive_joint"}
_OPEN = ("open",)
_CLOSED = ("close", "closed")


def read_srdf(root: ET.Element, src: str, joints: Mapping[str, tuple[str, str, str | None, str]], links: set[str],
              side: dict, where: str) -> dict[str, Any]:
    """Sidecar fields from a parsed SRDF (``root``; ``src`` names its file in messages).

    ``joints``: URDF joint name -> (type, child link, joint it mimics or None, parent link); ``links``: URDF link
    names; ``side``: the sidecar (``arm_group``, ``gripper_group``, ``gripper`` are read).
    Returns ``allowed_collisions``, ``named_poses_by_joint``, ``passive_joints``, ``notes`` and, when
    found, ``tcp_link``, ``gripper_joint``, ``gripper`` and ``planned_joints`` (the joints of the arm
    group and the gripper joint: a movable joint in neither is held still, as MoveIt leaves it).
    """
    groups: dict[str, ET.Element] = {}
    notes: list[str] = []
    passive: list[str] = []

    def note(text: str) -> None:
        if text not in notes:
            notes.append(text)

    def known(name: str | None, names: Mapping[str, Any] | set[str], kind: str, what: str) -> bool:
        """Whether ``name`` is a URDF joint/link; if not, a note: srdfdom skips such an element (and logs it)."""
        if name is not None and name in names:
            return True
        note(f"{src}: {what}: '{name}' is not a {kind} of the URDF: skipped (as srdfdom does)")
        return False

    for el in root:
        if not isinstance(el.tag, str):
            continue
        if el.tag not in _KNOWN:
            notes.append(f"{src}: <{el.tag}> not used (roarmctl reads {', '.join(sorted(_KNOWN - {'disable_default_collisions'}))})")
            continue
        if el.tag == "group":
            groups[el.get("name", "")] = el
        if el.tag == "virtual_joint" and el.get("type") != "fixed":
            raise DescriptionError(f"{src}: virtual_joint '{el.get('name')}': type '{el.get('type')}' is not supported "
                                   f"(only a fixed mounting)")
        if el.tag == "disable_default_collisions":
            raise DescriptionError(f"{src}: disable_default_collisions is not supported; list the pairs instead")
        if el.tag == "passive_joint" and known(el.get("name"), joints, "joint", "passive_joint"):
            passive.append(str(el.get("name")))

    def check_link(name: str | None, what: str) -> str:
        if name is None or name not in links:
            raise DescriptionError(f"{src}: {what}: '{name}' is not a link of the URDF")
        return name

    def chain_ok(chain: ET.Element, gname: str) -> bool:
        return all([known(chain.get(end), links, "link", f"group '{gname}' chain {end}") for end in ("base_link", "tip_link")])

    for gname, g in groups.items():  # every group's chain is checked, used or not; srdfdom skips a bad one
        for chain in g.findall("chain"):
            if not chain_ok(chain, gname):
                g.remove(chain)
    out: dict[str, Any] = {"passive_joints": passive, "notes": notes}
    pairs = []
    for el in root.iter("disable_collisions"):
        if all([known(el.get(k), links, "link", f"disable_collisions {k}") for k in ("link1", "link2")]):
            pairs.append([str(el.get("link1")), str(el.get("link2"))])
    out["allowed_collisions"] = pairs

    def group_joints(name: str, seen: tuple[str, ...] = ()) -> list[str]:
        g = groups.get(name)
        if g is None:
            raise DescriptionError(f"{src}: group '{name}' is not defined")
        js: list[str] = []
        for el in g:
            if el.tag == "joint":
                if known(el.get("name"), joints, "joint", f"group '{name}' joint"):
                    js.append(str(el.get("name")))
            elif el.tag == "link":
                if known(el.get("name"), links, "link", f"group '{name}' link"):
                    js.extend(j for j, (_, child, _m, _p) in joints.items() if child == el.get("name"))
            elif el.tag == "chain":  # the joints from the base link down to the tip
                base = check_link(el.get("base_link"), f"group '{name}' chain base_link")
                link = check_link(el.get("tip_link"), f"group '{name}' chain tip_link")
                up = {child: (j, parent) for j, (_, child, _m, parent) in joints.items()}
                chain: list[str] = []
                while link != base and link in up:
                    chain.append(up[link][0])
                    link = up[link][1]
                js.extend(reversed(chain))
            elif el.tag == "group":
                inner = el.get("name", "")
                if inner in seen:
                    raise DescriptionError(f"{src}: group '{name}' includes itself")
                js.extend(group_joints(inner, seen + (name,)))
            elif isinstance(el.tag, str):  # srdfdom reads only these four inside a group and skips the rest
                note(f"{src}: group '{name}': <{el.tag}> not read inside a group (srdfdom reads joint, link, chain and "
                     "group there; it skips the rest)")
        return js

    def driven(name: str) -> list[str]:
        """The group's joints that a motor drives: movable, not mimicking another, not passive."""
        return [j for j in dict.fromkeys(group_joints(name))
                if joints[j][0] != "fixed" and joints[j][2] is None and j not in passive]

    for key in ("gripper_group", "arm_group"):
        value = side.get(key)
        if value is not None and value not in groups:
            raise DescriptionError(f"{where}: {key}: '{value}' is not a group of {Path(src).name} (groups: {', '.join(groups)})")
    side_grip = side.get("gripper") if isinstance(side.get("gripper"), dict) else None
    ees = list(root.iter("end_effector"))
    grip_group = side.get("gripper_group")
    if grip_group is not None:
        if side_grip is None and len(driven(grip_group)) != 1:
            moved = driven(grip_group)
            raise DescriptionError(f"{src}: gripper group '{grip_group}' drives {len(moved)} joints "
                                   f"({', '.join(moved) or 'none'}); roarmctl drives one gripper joint",
                                   "name the gripper joint in the sidecar: gripper: {joint, open, closed}")
    else:
        candidates = [e.get("group") for e in ees] + [n for n in groups if n.lower() in ("gripper", "hand")]
        for c in dict.fromkeys(c for c in candidates if c in groups):
            if side_grip is not None and side_grip.get("joint") in group_joints(c):
                grip_group = c
                break
            if side_grip is None and len(driven(c)) == 1:
                grip_group = c
                break
        if grip_group is None and side_grip is None and candidates:
            notes.append(f"{src}: no group drives exactly one joint ({', '.join(dict.fromkeys(c for c in candidates if c in groups))}"
                         "): no gripper taken from the SRDF (give gripper: {joint, open, closed} in the sidecar)")
    ee = next((e for e in ees if e.get("group") == grip_group), ees[0] if ees else None)
    arm_group = side.get("arm_group") or next((n for n, g in groups.items() if g.find("chain") is not None
                                               and n != grip_group), None)
    if arm_group is None and grip_group is not None:  # an arm group given as joints: the other group
        # holding only non-gripper movable joints and not composed of groups (e.g. Franka's 'arm')
        plain = [n for n, g in groups.items() if n != grip_group and g.find("group") is None and g.find("chain") is None]
        arm_group = plain[0] if len(plain) == 1 else None
    if arm_group is not None:
        arm_chain = groups[arm_group].find("chain")
        if arm_chain is not None:
            out["tcp_link"] = arm_chain.get("tip_link")
        elif ee is not None and ee.get("parent_link"):  # no chain: the end effector's mounting link
            out["tcp_link"] = check_link(ee.get("parent_link"), "end_effector parent_link")
    gripper_joint = None
    if side_grip is not None:
        gripper_joint = side_grip.get("joint")
    elif grip_group is not None:
        gripper_joint = driven(grip_group)[0]
        out["gripper_joint"] = gripper_joint
    poses: dict[str, dict[str, float]] = {}
    grip_states: dict[str, float] = {}
    for gs in root.iter("group_state"):
        name, group = gs.get("name", ""), gs.get("group")
        values: dict[str, float] = {}
        for j in gs.findall("joint"):
            if not known(j.get("name"), joints, "joint", f"group_state '{name}' joint"):
                continue
            jname = str(j.get("name"))
            try:
                values[jname] = float(j.get("value", ""))
            except (TypeError, ValueError):
                raise DescriptionError(f"{src}: group_state '{name}' joint '{jname}' value: not a number: "
                                       f"{str(j.get('value'))[:40]!r}") from None
            if not math.isfinite(values[jname]):
                raise DescriptionError(f"{src}: group_state '{name}' joint '{jname}' value: not a finite number: "
                                       f"{j.get('value')!r}")
        if group == grip_group and grip_group is not None:
            grip_states[str(name).lower()] = values.get(gripper_joint, math.nan) if gripper_joint else math.nan
        elif group == arm_group:
            poses[name] = values
        elif group in groups and arm_group is not None and {g.get("name") for g in groups[group].findall("group")} \
                >= {arm_group} and set(group_joints(group)) <= set(group_joints(arm_group)) | {gripper_joint}:
            poses[name] = values  # a group of the arm and gripper groups: a pose with the gripper's value
        else:
            notes.append(f"{src}: group_state '{name}' of group '{group}' not used (neither the arm group "
                         f"'{arm_group}' nor the gripper group '{grip_group}'; name them with arm_group / gripper_group)")
    out["named_poses_by_joint"] = poses
    if arm_group is not None:  # what MoveIt plans: the arm and gripper groups' joints (others stay still)
        out["planned_joints"] = driven(arm_group) + ([gripper_joint] if gripper_joint else [])
    if gripper_joint is not None and side_grip is None:
        opened = next((grip_states[k] for k in _OPEN if k in grip_states), None)
        closed = next((grip_states[k] for k in _CLOSED if k in grip_states), None)
        if opened is not None and closed is not None and math.isfinite(opened) and math.isfinite(closed):
            out["gripper"] = {"joint": gripper_joint, "open": opened, "closed": closed}
    return out


def parse_srdf(path: Path, side: dict, sidecar: Path, where: str) -> tuple[ET.Element, str]:
    """The SRDF's XML root and its name for messages: read inside the description's roots (``side['_roots']``),
    a ``.xacro`` SRDF expanded like the URDF (the sidecar's ``xacro_args`` and ``packages``, the same roots)."""
    from roarmctl.robot.meshes import description_roots

    roots = side.get("_roots") or description_roots(side, sidecar)
    if path.suffix.lower() == ".xacro":
        text = expand(path, side.get("xacro_args"), where, roots=roots, trusted=bool(side.get("_trusted")))
        try:
            return ET.fromstring(text), str(path)
        except ET.ParseError as exc:
            raise DescriptionError(f"{path}: xacro output is not valid XML ({exc})") from None
    text = check_markup(read_text(path, f"{where}: srdf", SRDF_BYTES, roots=roots, error=DescriptionError,
                                  hint="the path is relative to the sidecar YAML"), str(path), DescriptionError)
    try:
        return ET.fromstring(text), str(path)
    except ET.ParseError as exc:
        raise DescriptionError(f"{path}: not valid XML ({exc})") from None


_JL_KEYS = {"has_velocity_limits", "max_velocity", "has_acceleration_limits", "max_acceleration",
            "has_position_limits", "min_position", "max_position", "has_jerk_limits", "max_jerk",
            "has_effort_limits", "max_effort", "angle_wraparound"}


def read_joint_limits(path: Path, joints: set[str], where: str,
                      roots: Roots | None = None) -> dict[str, dict[str, float]]:
    """MoveIt joint_limits.yaml -> {joint: {velocity, acceleration, lower, upper}} (only the limits in force).

    Read by ``roarmctl.validation.load_yaml`` (size, nesting, UTF-8, inside ``roots``)."""
    data = load_yaml(path, DescriptionError, what=f"{where}: joint_limits", roots=roots, empty_ok=True) or {}
    src = str(path)
    if not isinstance(data, dict):
        raise DescriptionError(f"{src}: expected a mapping at the top level")
    for key in ("default_velocity_scaling_factor", "default_acceleration_scaling_factor"):
        v = data.get(key, 1.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 1:
            raise DescriptionError(f"{src}: {key}: expected a number in (0, 1], got {v!r}")
    unknown = set(data) - {"joint_limits", "default_velocity_scaling_factor", "default_acceleration_scaling_factor"}
    if unknown:
        raise DescriptionError(f"{src}: unknown key(s) {sorted(unknown)}")
    out: dict[str, dict[str, float]] = {}
    limits = data.get("joint_limits") or {}
    if not isinstance(limits, dict):
        raise DescriptionError(f"{src}: joint_limits: expected a mapping joint -> limits, got {describe_value(limits)}")
    for jname, spec in limits.items():
        loc = f"{src}: joint_limits.{jname}"
        if jname not in joints:
            raise DescriptionError(f"{loc}: not a joint of the URDF")
        if not isinstance(spec, dict):
            raise DescriptionError(f"{loc}: expected a mapping")
        bad = set(spec) - _JL_KEYS
        if bad:
            raise DescriptionError(f"{loc}: unknown key(s) {sorted(bad)}")

        def num(key: str, spec: dict = spec, loc: str = loc) -> float:
            v = spec.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DescriptionError(f"{loc}.{key}: expected a number, got {v!r}")
            return float(v)

        got: dict[str, float] = {}
        for flag, key, name in (("has_velocity_limits", "max_velocity", "velocity"),
                                ("has_acceleration_limits", "max_acceleration", "acceleration")):
            if spec.get(flag) is True:
                v = num(key)
                if v <= 0:
                    raise DescriptionError(f"{loc}.{key}: must be positive when {flag} is true")
                got[name] = v
        if spec.get("has_position_limits") is True:
            got["lower"], got["upper"] = num("min_position"), num("max_position")
            if got["lower"] >= got["upper"]:
                raise DescriptionError(f"{loc}: min_position must be below max_position")
        if spec.get("has_jerk_limits") is True:
            raise DescriptionError(f"{loc}.has_jerk_limits: jerk limits are not supported by roarmctl's timing",
                                   "set has_jerk_limits: false")
        out[jname] = got
    return out
