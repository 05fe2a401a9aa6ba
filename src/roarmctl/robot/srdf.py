"""MoveIt's SRDF, turned into sidecar fields (joint_limits.yaml: ``robot.joint_limits``).

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
- ``disable_default_collisions link=L``: L's pairs with every other link of the robot are allowed, except the
  ``enable_collisions`` pairs, which re-enable what the default disabled (srdfdom's ``model.h``: "links that
  should have collision checking disabled by default (and only selectively enabled)"); L is still checked
  against the scene;
- ``virtual_joint`` of type fixed is accepted (the URDF root is fixed to the world).
Other groups' states and unknown elements are left out with a note (``notes``), and so is what srdfdom
skips (its ``model.cpp`` logs and goes on): an element inside a ``<group>`` other than joint, link, chain and
group (``<passive_joint>`` written there), a joint or link the URDF does not have (in a group, a chain, a
``passive_joint``, a ``disable_collisions``/``enable_collisions`` pair, a ``disable_default_collisions``, a
``group_state``), a ``group_state`` joint without a value. A ``group_state`` joint value is read as srdfdom reads
it (``srdfdom_values``: C++ stream extraction, so ``abc`` is 0), with a note where the text is not one plain
number; a joint whose value srdfdom reads as no number or as several is left out of the state, as MoveIt leaves
it, and a state without a value for every arm joint is left out with a note. A floating virtual joint is an error.
"""

from __future__ import annotations

import math
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from roarmctl.errors import DescriptionError
from roarmctl.fileio import read_text
from roarmctl.robot.xacro_input import expand
from roarmctl.validation import check_markup

SRDF_BYTES = 16 * 1024 * 1024  # an SRDF may have (MoveIt's of published arms: < 100 KiB)
_KNOWN = {"group", "group_state", "disable_collisions", "end_effector", "virtual_joint", "disable_default_collisions",
          "enable_collisions", "passive_joint"}
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
    no_default: list[str] = []  # disable_default_collisions links

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
            notes.append(f"{src}: <{el.tag}> not used (roarmctl reads {', '.join(sorted(_KNOWN))})")
            continue
        if el.tag == "group":
            groups[el.get("name", "")] = el
        if el.tag == "virtual_joint" and el.get("type") != "fixed":
            raise DescriptionError(f"{src}: virtual_joint '{el.get('name')}': type '{el.get('type')}' is not supported "
                                   f"(only a fixed mounting)")
        if el.tag == "disable_default_collisions" and known(el.get("link"), links, "link", "disable_default_collisions"):
            no_default.append(str(el.get("link")))
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
    pairs, enabled = [], set()
    for tag in ("disable_collisions", "enable_collisions"):
        for el in root.iter(tag):
            if all([known(el.get(k), links, "link", f"{tag} {k}") for k in ("link1", "link2")]):
                if tag == "enable_collisions":
                    enabled.add(frozenset((str(el.get("link1")), str(el.get("link2")))))
                else:
                    pairs.append([str(el.get("link1")), str(el.get("link2"))])
    for link in dict.fromkeys(no_default):
        pairs += [[link, other] for other in sorted(links) if other != link and frozenset((link, other)) not in enabled]
        note(f"{src}: disable_default_collisions '{link}': its collisions with the robot's other links are not "
             f"checked{' except the enable_collisions pairs' if any(link in p for p in enabled) else ''} (with the scene "
             "they are)")
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
            jname, text = str(j.get("name")), j.get("value")
            where_value = f"{src}: group_state '{name}' joint '{jname}'"
            if text is None:
                note(f"{where_value}: no value: skipped (as srdfdom does)")
                continue
            read = srdfdom_values(text)
            shown = text if len(text) <= 40 else text[:37] + "..."
            if len(read) != 1 or read[0] is None:
                said = "no number" if read == [None] else ", ".join(f"{v:g}" for v in read if v is not None)
                note(f"{where_value}: value '{shown}' is read by srdfdom as {said}, not one number: the joint is left "
                     "out of the state (as MoveIt leaves it)")
                continue
            values[jname] = read[0]
            if not _plain_number(text):
                note(f"{where_value}: value '{shown}' is not a number: read as {read[0]:g}, as srdfdom reads it")
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


_WS = " \t\n\v\f\r"  # C's isspace in the "C" locale
_MANTISSA = re.compile(r"[+-]?[0-9]*(?:\.[0-9]*)?")
_EXPONENT = re.compile(r"[eE][+-]?[0-9]*")
_DOUBLE_MAX = sys.float_info.max


def _plain_number(text: str) -> bool:
    """Whether ``text`` is one finite decimal number and nothing else (spaces around it aside)."""
    return _extract(text.strip(_WS), 0) == (len(text.strip(_WS)), True) and math.isfinite(float(text))


def _extract(text: str, pos: int) -> tuple[int, bool]:
    """C++'s ``operator>>(double&)`` from ``pos`` (after the leading white space): where the characters it takes end,
    and whether they make a number (libstdc++'s ``num_get``: a sign, digits, one point, digits, then an exponent only
    after a digit; what strtod cannot read whole is a failure)."""
    m = _MANTISSA.match(text, pos)
    end = m.end() if m else pos
    if any(c.isdigit() for c in text[pos:end]):
        e = _EXPONENT.match(text, end)
        if e:
            end = e.end()
    try:
        float(text[pos:end])
        return end, True
    except ValueError:
        return end, False


def srdfdom_values(text: str) -> list[float | None]:
    """The numbers srdfdom's ``loadGroupStates`` stores for a ``group_state`` joint's ``value`` text: its loop
    ``while (ss.good() && !ss.eof()) { ss >> val >> std::ws; push_back(val); }`` on an ``istringstream``.

    A failed extraction stores 0 and ends the loop (``abc`` -> [0], ``1.5abc`` -> [1.5, 0]); an overflow stores the
    largest double with its sign and ends it; an empty or blank text stores a value the C++ leaves undefined (None).
    """
    out: list[float | None] = []
    n, pos = len(text), 0
    while pos < n and text[pos] in _WS:
        pos += 1
    if pos >= n:
        return [None]
    while True:
        start = pos
        pos, ok = _extract(text, start)
        if not ok:
            out.append(0.0)
            return out
        value = float(text[start:pos])
        if math.isinf(value):  # strtod's overflow: the largest double, and the stream fails
            out.append(math.copysign(_DOUBLE_MAX, value))
            return out
        out.append(value)
        while pos < n and text[pos] in _WS:
            pos += 1
        if pos >= n:
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
