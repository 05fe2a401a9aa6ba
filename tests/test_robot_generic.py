"""Nothing robot-specific outside the descriptions: link roles, singularity dimensions and the IK
family come from the robot's own files (issue 8, item 3)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from clirun import roarmctl

from roarmctl.errors import DescriptionError
from roarmctl.robot.ik import solve_ik
from roarmctl.robot.loader import bundled_dir, load_robot
from roarmctl.robot.singularity import classify_singularity

PKG = Path(__file__).resolve().parents[1] / "src" / "roarmctl"

# Universal Robots' published standard-DH table of the UR10 (metres, radians).
UR10_STANDARD = {
    "format": "roarmctl.robot/1",
    "name": "ur10_std",
    "convention": "standard",
    "singularity_model": "ur6",
    "dh": [
        {"name": "j1", "a": 0, "alpha": math.pi / 2, "d": 0.1273, "lower": -6.28, "upper": 6.28},
        {"name": "j2", "a": -0.612, "alpha": 0, "d": 0, "lower": -6.28, "upper": 6.28},
        {"name": "j3", "a": -0.5723, "alpha": 0, "d": 0, "lower": -6.28, "upper": 6.28},
        {"name": "j4", "a": 0, "alpha": math.pi / 2, "d": 0.163941, "lower": -6.28, "upper": 6.28},
        {"name": "j5", "a": 0, "alpha": -math.pi / 2, "d": 0.1157, "lower": -6.28, "upper": 6.28},
        {"name": "j6", "a": 0, "alpha": 0, "d": 0.0922, "lower": -6.28, "upper": 6.28},
    ],
}


@pytest.mark.slow
def test_no_roarm_link_names_outside_descriptions():
    """The planner, device, drawing and CLI code never names a RoArm link or joint."""
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
    names = set(re.findall(r'<(?:link|joint) name="([^"]+)"', urdf)) - {"world"}  # "world" is plain English
    assert {"base_link", "link1", "gripper_link", "hand_tcp"} <= names
    hits = []
    for sub in ("motion", "device", "viz", "cli"):
        for py in (PKG / sub).rglob("*.py"):
            text = py.read_text()
            for n in names:
                if re.search(rf"\b{re.escape(n)}\b", text):
                    hits.append(f"{py.relative_to(PKG)}: {n}")
    assert not hits, hits


def test_link_roles_from_sidecar_and_defaults(tmp_path):
    m3 = load_robot("roarm_m3_pro")
    assert set(m3.base_links) == {"world", "base_link", "link1"}
    assert set(m3.jaw_links) == {"link5", "gripper_link"}
    # without the sidecar fields: the root with the links fixed to it; the gripper's two links
    side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
    del side["base_links"], side["jaw_links"]
    side["urdf"] = str(bundled_dir() / "roarm_m3_pro.urdf")
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(side))
    r = load_robot(str(tmp_path / "r.yaml"))
    assert set(r.base_links) == {"world", "base_link"}
    assert {"link5", "gripper_link"} <= set(r.jaw_links)
    side["jaw_links"] = ["link5", "nope"]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(side))
    with pytest.raises(DescriptionError, match=r"jaw_links: 'nope' is not a link"):
        load_robot(str(tmp_path / "bad.yaml"))


def _ur10_std(tmp_path, mutate=None) -> Path:
    data = yaml.safe_load(yaml.safe_dump(UR10_STANDARD))
    if mutate:
        mutate(data)
    p = tmp_path / "ur10_std.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def test_ur6_standard_dh_table_solves_like_modified(tmp_path):
    """The standard-DH UR10 (negative a, opposite twists) gets the analytic IK: every solution
    reaches the FK target, and the configuration the target came from is among them."""
    robot = load_robot(str(_ur10_std(tmp_path)))
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-2.5, 2.5, 6)
        t = robot.kin.fk(q)
        from roarmctl.robot.model import rpy_from_matrix

        sols = solve_ik(robot, t[:3, 3], rpy=rpy_from_matrix(t[:3, :3]), all_solutions=True)
        assert 1 <= len(sols) <= 8
        for s in sols:
            ts = robot.kin.fk(s)
            assert np.linalg.norm(ts[:3, 3] - t[:3, 3]) < 1e-6
            assert np.allclose(ts[:3, :3], t[:3, :3], atol=1e-5)
        d = [np.max(np.abs((s - q + np.pi) % (2 * np.pi) - np.pi)) for s in sols]
        assert min(d) < 1e-5


def test_ur6_singularity_uses_the_tables_dimensions(tmp_path):
    """Shoulder singularity where a2 c2 + a3 c23 - d5 s234 = 0 with this table's numbers (not the
    bundled ur10.yaml's); the Jacobian confirms the rank loss there and not 0.3 rad away."""
    robot = load_robot(str(_ur10_std(tmp_path)))
    assert classify_singularity(robot, [0.3, 0.4, 1e-4, 0.2, 1.0, 0.0]) == "elbow"
    a2, a3, d5 = -0.612, -0.5723, 0.1157
    th2, th3 = 1.2, 0.9
    th234 = math.asin((a2 * math.cos(th2) + a3 * math.cos(th2 + th3)) / d5)
    # the standard table's twists (+90, -90 at the wrist) put pi on joints 4 and 6 of the modified-DH model
    q = np.array([0.1, th2, th3, th234 - th2 - th3 - math.pi, 1.0, 0.0])
    sv = np.linalg.svd(robot.kin.jacobian(q), compute_uv=False)
    assert sv[-1] < 1e-9
    assert classify_singularity(robot, q) == "shoulder"
    q[3] += 0.3
    assert np.linalg.svd(robot.kin.jacobian(q), compute_uv=False)[-1] > 1e-3
    assert classify_singularity(robot, q) is None


@pytest.mark.parametrize("mutate, needle", [
    (lambda d: d["dh"][3].update(alpha=0.7), r"dh\[3\]\.alpha"),
    (lambda d: d["dh"][0].update(a=0.05), r"a_1 = 0.05"),
    (lambda d: d["dh"].pop(), r"6 revolute rows"),
])
def test_ur6_refuses_a_table_it_cannot_serve(tmp_path, mutate, needle):
    path = _ur10_std(tmp_path, mutate)
    with pytest.raises(DescriptionError, match=needle):
        load_robot(str(path))
    proc = roarmctl("kin", "fk", str(path), "0", "0", "0", "0", "0", "0")
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr


def test_unknown_ik_family_is_an_error(tmp_path):
    p = _ur10_std(tmp_path, lambda d: d.update(ik="magic"))
    with pytest.raises(DescriptionError, match="ik: unknown IK family 'magic'"):
        load_robot(str(p))
    p = _ur10_std(tmp_path, lambda d: d.update(singularity_model="ur7"))
    with pytest.raises(DescriptionError, match="singularity_model: unknown model 'ur7'"):
        load_robot(str(p))


@pytest.mark.slow
def test_renamed_links_plan_pick_and_place_exactly_as_the_original(tmp_path):
    """Every link and joint of the M3 renamed (URDF and sidecar alike): the bundled pick-and-place
    gives the same trajectory, sample for sample."""
    from roarmctl.motion.pipeline import plan_file

    rename = {"base_link": "pedestal", "link1": "turret", "link2": "upper_arm", "link3": "forearm",
              "link4": "wrist", "link5": "palm", "gripper_link": "finger", "hand_tcp": "tool_point"}

    def renamed(text: str) -> str:
        for old, new in rename.items():
            text = re.sub(rf"(?<![A-Za-z0-9]){old}(?![0-9]|s:)", new, text)  # not the 'base_links:' key
        return text

    urdf = renamed((bundled_dir() / "roarm_m3_pro.urdf").read_text())
    assert "link1" not in urdf and "base_link" not in urdf
    (tmp_path / "arm.urdf").write_text(urdf)
    side = yaml.safe_load(renamed((bundled_dir() / "roarm_m3_pro.yaml").read_text()))
    side["urdf"] = "arm.urdf"
    for m in side["gripper"]["jaw_meshes"]:  # the jaws' pieces beside the URDF, under their renamed links' names
        (tmp_path / m["pieces"]).parent.mkdir(parents=True, exist_ok=True)
        original = {v: k for k, v in rename.items()}[m["link"]]
        (tmp_path / m["pieces"]).write_bytes((bundled_dir() / "jaw_pieces" / f"roarm_m3_{original}.json").read_bytes())
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    plans = Path(__file__).resolve().parents[1] / "plans"
    plan = yaml.safe_load((plans / "pick_place.yaml").read_text())
    plan["robot"] = "arm.yaml"
    (tmp_path / "pick_place.yaml").write_text(yaml.safe_dump(plan))
    original = plan_file(plans / "pick_place.yaml").trajectory
    other = plan_file(tmp_path / "pick_place.yaml").trajectory
    assert other.joint_names == [renamed(n) for n in original.joint_names] != original.joint_names
    assert np.array_equal(original.times, other.times)
    assert np.array_equal(original.positions, other.positions)
    assert [e.kind for e in original.events] == [e.kind for e in other.events]



TOWER = """<robot name="tower">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="post"><collision><origin xyz="0 0 0.05"/><geometry><box size="0.05 0.05 0.2"/></geometry></collision></link>
  <link name="boom"><collision><origin xyz="0.1 0 0"/><geometry><box size="0.2 0.03 0.03"/></geometry></collision></link>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="post"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="pitch" type="revolute"><parent link="post"/><child link="boom"/><origin xyz="0 0 0.15"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>"""


def test_links_joined_by_a_joint_may_touch_without_listing_them(tmp_path):
    """A bare URDF whose post sinks into the base and whose boom starts inside the post (as meshes do
    at their joints): FCL on the raw boxes says both joined pairs overlap, yet the arm is valid; the
    boom swung down into the base (not joined to it) is still a collision."""
    import fcl

    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene

    (tmp_path / "tower.urdf").write_text(TOWER)
    robot = load_robot(str(tmp_path / "tower.urdf"))
    q = np.zeros(2)
    frames = robot.kin.link_frames(q)

    def box(link):
        s = next(c for c in robot.collision if c.link == link)
        t = frames[robot.kin.link_index[link]] @ s.origin
        return fcl.CollisionObject(fcl.Box(*s.size), fcl.Transform(t[:3, :3], t[:3, 3]))

    for a, b in (("base", "post"), ("post", "boom")):
        assert fcl.collide(box(a), box(b), fcl.CollisionRequest(), fcl.CollisionResult())
    checker = CollisionChecker(robot, Scene(items=[]), padding=0.0)
    assert checker.is_valid(q)
    assert not checker.is_valid(np.array([0.0, 1.57]))  # boom pointing down, into the base


LIFT = """<robot name="lift">
  <link name="base"/>
  <link name="carriage"><inertial><mass value="2.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="counterweight"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="left"><inertial><mass value="0"/></inertial></link><link name="right"><inertial><mass value="0"/></inertial></link>
  <joint name="z" type="prismatic"><parent link="base"/><child link="carriage"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.5" effort="100" velocity="1"/></joint>
  <joint name="z2" type="prismatic"><parent link="base"/><child link="counterweight"/><origin xyz="0.3 0 0.2"/>
    <axis xyz="0 0 1"/><limit lower="-0.5" upper="0.5" effort="100" velocity="1"/><mimic joint="z" multiplier="%s" offset="0.01"/></joint>
  <joint name="grip" type="prismatic"><parent link="carriage"/><child link="left"/><origin xyz="0 0.02 0"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="10" velocity="0.1"/></joint>
  <joint name="grip2" type="prismatic"><parent link="carriage"/><child link="right"/><origin xyz="0 -0.02 0"/>
    <axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="10" velocity="0.1"/><mimic joint="grip"/></joint>
</robot>"""


@pytest.mark.parametrize("mult", [1, -1, 0.5, -0.676])
def test_mimic_joints_follow_their_joint(tmp_path, mult):
    """URDF <mimic>: the mimicking joints are not actuated; FK puts their links where multiplier x q +
    offset does (by hand), and RNEA adds their load to the joint they follow: holding the 2 kg
    carriage with the 0.5 kg counterweight mimicking it needs (2 + m 0.5) g N (virtual work: the
    counterweight moves m times as far; -1 moves it the other way). -0.676 is the Kinova Gen3 lite
    finger tip's multiplier (Kinovarobotics/ros2_kortex, gen3_lite.urdf)."""
    from roarmctl.robot.dynamics import gravity_vector

    (tmp_path / "lift.urdf").write_text(LIFT % mult)
    robot = load_robot(str(tmp_path / "lift.urdf"))
    assert robot.joint_names == ["z", "grip"]
    q = np.array([0.2, 0.03])
    f = robot.kin.link_frames(q)
    at = lambda link: f[robot.kin.link_index[link]][:3, 3]  # noqa: E731
    np.testing.assert_allclose(at("counterweight"), [0.3, 0, 0.2 + mult * 0.2 + 0.01], atol=1e-12)
    np.testing.assert_allclose(at("left"), [0, 0.02 + 0.03, 0.3], atol=1e-12)
    np.testing.assert_allclose(at("right"), [0, -0.02 - 0.03, 0.3], atol=1e-12)
    g = 9.81
    np.testing.assert_allclose(gravity_vector(robot, q), [(2.0 + mult * 0.5) * g, 0.0], atol=1e-9)


def test_revolute_mimic_with_a_multiplier_turns_that_much(tmp_path):
    """A revolute finger mimicking with multiplier -0.676 and offset 0.149 (the Gen3 lite's tip joint)
    turns by -0.676 q + 0.149 rad about its axis: its child's frame is Rz of that angle, by hand."""
    urdf = """<robot name="f"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
        <limit lower="0" upper="0.85" effort="1" velocity="1"/></joint>
      <joint name="k" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.1 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="j" multiplier="-0.676" offset="0.149"/></joint>
    </robot>"""
    (tmp_path / "f.urdf").write_text(urdf)
    robot = load_robot(str(tmp_path / "f.urdf"))
    q = 0.6
    rel = np.linalg.inv(robot.kin.fk(np.array([q]), "b")) @ robot.kin.fk(np.array([q]), "c")
    a = -0.676 * q + 0.149
    np.testing.assert_allclose(rel[:3, :3], [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]], atol=1e-12)
    np.testing.assert_allclose(rel[:3, 3], [0.1, 0, 0], atol=1e-12)


def test_a_finger_that_mimics_the_gripper_is_a_jaw(tmp_path):
    """Both fingers of a parallel gripper whose second finger mimics the first are jaws (they may touch
    the grasped object) and both move when the gripper closes (checked against the object then)."""
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene

    (tmp_path / "lift.urdf").write_text(LIFT % 1)
    (tmp_path / "lift.yaml").write_text(yaml.safe_dump({"format": "roarmctl.robot/1", "urdf": "lift.urdf",
                                                        "gripper": {"joint": "grip", "open": 0.04, "closed": 0.0}}))
    robot = load_robot(str(tmp_path / "lift.yaml"))
    assert {"left", "right", "carriage"} <= set(robot.jaw_links)
    assert set(CollisionChecker(robot, Scene(items=[])).moving_jaw_links) == {"left", "right"}
