"""roarmctl's URDF reading against urdfdom's, through Pinocchio (issue 33, item 1).

Pinocchio (``pin`` from PyPI) parses a URDF with urdfdom itself (cmeel-urdfdom), so it is the reference for
what urdfdom accepts, and an independent forward kinematics. On the published descriptions of the xacro
corpus (tests/data/xacro/, expanded as real xacro does: tests/test_xacro_differential.py) with their mesh
geometry left out (the corpus keeps no meshes; urdfdom opens none): urdfdom accepts each, so roarmctl must,
and every link's pose at random joint values within the limits agrees with Pinocchio's to 1e-9 (mimic joints
follow their leader, joints roarmctl holds still sit at their held value). Values urdfdom takes that mean
"not given" (a negative or zero effort or velocity) load with a note, not a refusal.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from roarmctl.errors import DescriptionError
from roarmctl.robot.loader import bundled_dir, load_robot
from roarmctl.robot.xacro_input import expand

pin = pytest.importorskip("pinocchio")

from test_xacro_differential import CASES, INNER, job  # noqa: E402 - after the skip

URDF_CASES = sorted(n for n in CASES if not n.endswith("_srdf"))
RNG_SEED = 33
#: Published files that load only with a sidecar line: case -> (roarmctl's refusal, the sidecar fields). None
#: since a mimic joint of the arm (the IRB 5400's joint5b, which follows joint5 in the wrist) adds to its leader's
#: Jacobian column: test_a_mimic_joint_in_the_wrist_is_a_column_of_its_leader.
NEEDS_SIDECAR: dict[str, tuple[str, dict]] = {}


def for_pinocchio(urdf: str) -> str:
    """``urdf`` with negative efforts and velocities written as 0: urdfdom reads them, but Pinocchio's own model
    check (effort and velocity limits are symmetric bounds) refuses them. The kinematics are unchanged."""
    return re.sub(r'\b(effort|velocity)="\s*-[^"]*"', r'\1="0"', urdf)


def without_meshes(urdf: str) -> str:
    """``urdf`` with every ``<visual>`` and ``<collision>`` that names a mesh left out (kinematics unchanged)."""
    root = ET.fromstring(urdf)
    for link in root.iter("link"):
        for el in [e for e in link if e.tag in ("visual", "collision") and e.find("geometry/mesh") is not None]:
            link.remove(el)
    return ET.tostring(root, encoding="unicode")


def pin_frames(model, data, robot, q_full: np.ndarray) -> dict[str, np.ndarray]:
    """Pinocchio's pose of every link (4x4, root frame) for roarmctl's full configuration ``q_full``."""
    names, values, _ = robot.joint_states(q_full)
    value = dict(zip(names, values[0]))
    q = pin.neutral(model)
    for jid in range(1, model.njoints):
        name, jm = model.names[jid], model.joints[jid]
        v = value.get(name, 0.0)
        if jm.nq == 2:  # a continuous joint: (cos, sin)
            q[jm.idx_q:jm.idx_q + 2] = np.cos(v), np.sin(v)
        else:
            q[jm.idx_q] = v
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    out = {}
    for fid, frame in enumerate(model.frames):
        if frame.type == pin.FrameType.BODY:
            out[frame.name] = data.oMf[fid].homogeneous
    return out


@pytest.mark.parametrize("name", [pytest.param(n, marks=[] if n in INNER else [pytest.mark.slow]) for n in URDF_CASES])
def test_urdfdom_accepts_so_roarmctl_does_and_fk_agrees(tmp_path, name):
    j = job(name)
    urdf = without_meshes(expand(Path(j["file"]), j["args"], name, {p: Path(f) for p, f in j["packages"].items()}))
    model = pin.buildModelFromXML(for_pinocchio(urdf))  # urdfdom accepts it (it raises otherwise)
    path = tmp_path / f"{name}.urdf"
    path.write_text(urdf)
    if name in NEEDS_SIDECAR:
        refusal, fields = NEEDS_SIDECAR[name]
        with pytest.raises(DescriptionError, match=re.escape(refusal)):
            load_robot(str(path))
        (tmp_path / "arm.yaml").write_text(yaml.safe_dump({"format": "roarmctl.robot/1", "urdf": path.name, **fields}))
        path = tmp_path / "arm.yaml"
    robot = load_robot(str(path))
    data = model.createData()
    rng = np.random.default_rng(RNG_SEED)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    checked = 0
    for q in rng.uniform(lo, hi, size=(5, robot.dof)):
        ours = robot.kin.link_frames(q)
        theirs = pin_frames(model, data, robot, q)
        for k, link in enumerate(robot.link_names):
            assert np.allclose(ours[k], theirs[link], atol=1e-9, rtol=0), (link, q)
            checked += 1
    assert checked >= 5 * len(robot.link_names) and robot.dof >= 5


NEGATIVE = """<robot name="r">
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="{effort}" velocity="{velocity}"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="3" velocity="2"/></joint>
</robot>"""


@pytest.mark.parametrize("effort, velocity", [(-1, 2), (0, 2), (3, -1), (-5, -0.5), (3, 0)])
def test_a_negative_or_zero_effort_or_velocity_is_not_given_with_a_note(tmp_path, effort, velocity):
    """urdfdom reads any number for effort and velocity (vendors write -1 or 0 for "not given"): roarmctl loads
    the file, takes the value as not given (no effort bound; the default velocity) and says so."""
    yourdfpy = pytest.importorskip("yourdfpy")
    text = NEGATIVE.format(effort=effort, velocity=velocity)
    (tmp_path / "arm.urdf").write_text(text)
    limit = yourdfpy.URDF.load(str(tmp_path / "arm.urdf"), load_meshes=False).robot.joints[0].limit
    assert (limit.effort, limit.velocity) == (effort, velocity)  # read as given, as urdfdom reads it
    robot = load_robot(str(tmp_path / "arm.urdf"))
    assert robot.effort_limits[0] == (np.inf if effort <= 0 else effort)
    assert robot.effort_limits[1] == 3 and robot.velocity_limits[1] == 2
    if velocity <= 0:
        assert robot.velocity_limits[0] > 0 and "j1" in robot.defaults.get("velocity", [])
    else:
        assert robot.velocity_limits[0] == velocity
    if effort < 0 or velocity < 0:
        assert any("not given" in n and "j1" in n for n in robot.notes), robot.notes


def test_the_bundled_urdf_agrees_with_pinocchio():
    robot = load_robot("roarm_m3_pro")
    model = pin.buildModelFromUrdf(str(bundled_dir() / "roarm_m3_pro.urdf"))
    data = model.createData()
    for q in np.random.default_rng(RNG_SEED).uniform(robot.lower, robot.upper, size=(20, robot.dof)):
        theirs = pin_frames(model, data, robot, q)
        ours = robot.kin.link_frames(q)
        for k, link in enumerate(robot.link_names):
            assert np.allclose(ours[k], theirs[link], atol=1e-9, rtol=0), link


LIMITED = """<robot name="r">
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="3" velocity="2"/></joint>
  <joint name="j2" type="{kind}"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/>{limit}</joint>
</robot>"""
#: Each attribute of the varied joint's ``<limit>``: left out, or one of these values.
LIMIT_VALUES = {"lower": ("-1", "0.5"), "upper": ("2", "-2"), "effort": ("4",), "velocity": ("1.5",)}


def limit_variants():
    """Every joint type with no ``<limit>`` and with every choice of written attributes and values."""
    import itertools

    choices = [[(key, None)] + [(key, v) for v in values] for key, values in LIMIT_VALUES.items()]
    for kind in ("revolute", "prismatic", "continuous", "fixed"):
        yield kind, None
        for combo in itertools.product(*choices):
            yield kind, {k: v for k, v in combo if v is not None}


@pytest.mark.parametrize("kind, attrs", list(limit_variants()),
                         ids=lambda v: v if isinstance(v, str) else "-".join(f"{k}{x}" for k, x in (v or {}).items()) or "none")
def test_a_joint_limit_is_read_as_urdfdom_reads_it(tmp_path, kind, attrs):
    """The class of ``<limit>`` elements (attributes written or not, for every joint type), against urdfdom itself
    (through Pinocchio): what urdfdom refuses (a revolute or prismatic joint without ``<limit>``, a ``<limit>``
    without effort or velocity, urdf_parser/src/joint.cpp) roarmctl refuses with one line naming the joint; what it
    accepts roarmctl loads with the same bounds (a bound not written is 0), except where they leave no range
    (lower >= upper), which roarmctl refuses naming the bounds and, when one was not written, that it is 0."""
    limit = "" if attrs is None else "<limit " + " ".join(f'{k}="{v}"' for k, v in attrs.items()) + "/>"
    text = LIMITED.format(kind=kind, limit=limit)
    (tmp_path / "arm.urdf").write_text(text)
    try:
        model = pin.buildModelFromXML(text)
    except ValueError:
        model = None
    if model is None:
        with pytest.raises(DescriptionError) as err:
            load_robot(str(tmp_path / "arm.urdf"))
        message = str(err.value)
        assert "joint 'j2'" in message and "urdfdom" in message and "\n" not in message
        return
    if kind in ("revolute", "prismatic"):
        lower, upper = float(model.lowerPositionLimit[1]), float(model.upperPositionLimit[1])
        if not lower < upper:
            with pytest.raises(DescriptionError, match=r"joint 'j2' limit: lower .* must be below upper") as err:
                load_robot(str(tmp_path / "arm.urdf"))
            assert ("reads a missing bound as 0" in str(err.value)) == ("lower" not in attrs or "upper" not in attrs)
            return
        robot = load_robot(str(tmp_path / "arm.urdf"))
        assert (robot.lower[1], robot.upper[1]) == (lower, upper)
    else:
        robot = load_robot(str(tmp_path / "arm.urdf"))
        assert robot.dof == 1 + (kind == "continuous")


#: A box put on every link of the IRB 5400 for the sweep bound (its meshes are not in the corpus): corners (8, 3).
BOX_AT, BOX_SIZE = np.array([0.05, 0.02, 0.03]), 0.1
CORNERS = BOX_AT + BOX_SIZE / 2 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])


def _irb5400(tmp_path: Path):
    j = job("abb_irb5400")
    urdf = without_meshes(expand(Path(j["file"]), j["args"], "abb_irb5400", {p: Path(f) for p, f in j["packages"].items()}))
    root = ET.fromstring(urdf)
    for link in root.iter("link"):
        link.append(ET.fromstring(f'<collision><origin xyz="{" ".join(map(str, BOX_AT))}"/><geometry>'
                                  f'<box size="{BOX_SIZE} {BOX_SIZE} {BOX_SIZE}"/></geometry></collision>'))
    (tmp_path / "irb5400.urdf").write_text(ET.tostring(root, encoding="unicode"))
    return load_robot(str(tmp_path / "irb5400.urdf")), urdf


def test_a_mimic_joint_in_the_wrist_is_a_column_of_its_leader(tmp_path):
    """ABB's IRB 5400 (ros-industrial/abb, published): joint5b mimics joint5 between the wrist and the flange. It loads
    unchanged with the TCP at the flange; the Jacobian's joint5 column holds both joints' motion (the chain rule), so
    it equals the central difference of FK (an independent method) to 1e-7 at random joint values; the checker's
    singularity margin is its smallest singular value; the collision sweep bound holds for random steps (no point of
    a moving shape's bounding sphere centre moves further than sweep_gain times the step); IK reaches FK's poses."""
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene
    from roarmctl.robot.ik import solve_ik

    robot, urdf = _irb5400(tmp_path)
    assert "joint5b" not in robot.joint_names and robot.tcp_link == "tool0" and robot.arm_dof == 6
    assert next(j for j in robot.joints if j.name == "joint5b").mimic == "joint5"
    model = pin.buildModelFromXML(for_pinocchio(urdf))
    data = model.createData()
    rng = np.random.default_rng(RNG_SEED)
    checker = CollisionChecker(robot, Scene())
    eps = 1e-6
    for q in rng.uniform(robot.lower * 0.9, robot.upper * 0.9, size=(6, robot.dof)):
        jac = robot.kin.jacobian(q)
        tcp = robot.kin.fk(q)
        for k, i in enumerate(robot.arm_indices):
            dq = np.zeros(robot.dof)
            dq[i] = eps
            a, b = robot.kin.fk(q + dq), robot.kin.fk(q - dq)
            turn = (a[:3, :3] - b[:3, :3]) / (2 * eps) @ tcp[:3, :3].T
            fd = np.concatenate([(a[:3, 3] - b[:3, 3]) / (2 * eps), [turn[2, 1], turn[0, 2], turn[1, 0]]])
            assert np.allclose(jac[:, k], fd, atol=1e-7), (k, q)
        assert np.allclose(pin_frames(model, data, robot, q)["tool0"], tcp, atol=1e-9)
        sv = np.linalg.svd(jac[:3], compute_uv=False)[-1]
        assert checker.margin_measure(q[robot.arm_indices][None])[0] == pytest.approx(sv, rel=1e-9, abs=1e-12)
        step = rng.normal(size=robot.arm_dof) * 0.01
        q2 = q.copy()
        q2[robot.arm_indices] += step
        moving = sorted({robot.kin.link_index[s.link] for s in robot.collision} - {robot.kin.link_index[robot.root]})
        corners = [np.einsum("lij,cj->lci", f[moving, :3, :3], CORNERS) + f[moving, None, :3, 3]
                   for f in (robot.kin.link_frames(q), robot.kin.link_frames(q2))]
        assert checker.sweep_gain > 0
        assert np.linalg.norm(corners[1] - corners[0], axis=2).max() <= checker.sweep_gain * np.linalg.norm(step)
        (sol,) = solve_ik(robot, tcp[:3, 3], rpy=_rpy(tcp[:3, :3]), q_ref=q)[:1]
        reached = robot.kin.fk(sol)
        assert np.linalg.norm(reached[:3, 3] - tcp[:3, 3]) < 1e-4 and np.allclose(reached[:3, :3], tcp[:3, :3], atol=1e-3)


def _rpy(rot: np.ndarray) -> list[float]:
    """URDF roll-pitch-yaw of a rotation (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    return [float(np.arctan2(rot[2, 1], rot[2, 2])), float(np.arcsin(-np.clip(rot[2, 0], -1, 1))),
            float(np.arctan2(rot[1, 0], rot[0, 0]))]
