"""RoArm-M2-S (issue 8, item 4): Waveshare's MoveIt package loads as it is (plus a small sidecar),
agrees with the bundled ``roarm_m2_s``, and both plan the bundled example."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from roarmctl.robot.ik import solve_ik
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]
# ../shared beside the clone (CI, the main checkout); one level higher for a git worktree under wt/
VENDOR = next((d / "shared" / "reference" / "roarm_m3" / "m2s_roarm_ws_em0" for d in (ROOT.parent, ROOT.parent.parent)
               if (d / "shared" / "reference" / "roarm_m3" / "m2s_roarm_ws_em0").is_dir()),
              ROOT.parent / "shared" / "reference" / "roarm_m3" / "m2s_roarm_ws_em0")
needs_vendor = pytest.mark.skipif(not VENDOR.is_dir(), reason=f"Waveshare's M2-S package is not at {VENDOR} "
                                  "(CI has ../shared beside the clone; a bare clone does not)")


def vendor_sidecar(tmp_path: Path) -> Path:
    """What MoveIt lacks: the wire map (and the package folder); everything else from the package. The package
    is copied beside the sidecar: a description named by a plan or a trajectory reads only inside its own folder."""
    import shutil

    pkg = tmp_path / "roarm_description"
    if not pkg.exists():
        shutil.copytree(VENDOR, pkg)
    side = {
        "format": "roarmctl.robot/1",
        "name": "m2s_moveit",
        "urdf": str(pkg / "urdf" / "roarm_description.urdf"),
        "srdf": str(pkg / "config" / "roarm_description.srdf"),
        "joint_limits": str(pkg / "config" / "joint_limits.yaml"),
        "packages": {"roarm_description": str(pkg)},
        "ik": "roarm3",
        "base_links": ["base_link", "link1"],
        "limits": {"velocity": [2.0, 1.5, 1.8, 2.5], "acceleration": [5.0, 4.0, 5.0, 6.0]},
        "wire": [
            {"joint": "base_link_to_link1", "field": "base", "sign": -1},
            {"joint": "link1_to_link2", "field": "shoulder", "sign": -1},
            {"joint": "link2_to_link3", "field": "elbow"},
            {"joint": "link3_to_gripper_link", "field": "hand", "sign": -1, "offset": 3.1415926},
        ],
    }
    p = tmp_path / "m2s.yaml"
    p.write_text(yaml.safe_dump(side))
    return p


@needs_vendor
def test_moveit_package_loads_unchanged_and_agrees_with_bundled(tmp_path):
    vendor = load_robot(str(vendor_sidecar(tmp_path)))
    ours = load_robot("roarm_m2_s")
    # from the SRDF: TCP (chain tip), gripper (group 'gripper' + open/close states), home, allowed pairs
    assert vendor.tcp_link == "hand_tcp"
    assert (vendor.gripper.joint, vendor.gripper.open, vendor.gripper.closed) == ("link3_to_gripper_link", 1.5, 0.0)
    assert np.allclose(vendor.named_poses["home"], [0, 0, 1.5708, 0])
    assert frozenset(("gripper_link", "link3")) in vendor.allowed_collisions
    assert vendor.joint_names == ours.joint_names
    assert all(s.kind == "mesh" for s in vendor.collision) and len(vendor.collision) == 5
    # same kinematics: every link frame, at random configurations inside the common limits
    rng = np.random.default_rng(0)
    lo, hi = np.maximum(vendor.lower, ours.lower), np.minimum(vendor.upper, ours.upper)
    q = rng.uniform(lo, hi, (50, 4))
    fv, fo = vendor.kin.link_frames(q), ours.kin.link_frames(q)
    for name in ("base_link", "link1", "link2", "link3", "gripper_link", "hand_tcp"):
        a = fv[:, vendor.kin.link_index[name]]
        b = fo[:, ours.kin.link_index[name]]
        assert np.allclose(a, b, atol=1e-6), name


@needs_vendor
def test_bundled_boxes_contain_every_mesh_vertex():
    ours = load_robot("roarm_m2_s")
    for link in ("base_link", "link1", "link2", "link3", "gripper_link"):
        verts = trimesh.load(VENDOR / "meshes" / f"{link}.STL", force="mesh").vertices  # link frame (origin 0)
        inside = np.zeros(len(verts), dtype=bool)
        for s in (s for s in ours.collision if s.link == link):
            assert s.kind == "box"
            local = (verts - s.origin[:3, 3]) @ s.origin[:3, :3]
            inside |= np.all(np.abs(local) <= np.asarray(s.size) / 2 + 1e-9, axis=1)
        assert inside.all(), f"{link}: {np.count_nonzero(~inside)} vertices outside the boxes"


def test_position_only_ik_returns_the_configuration_fk_came_from():
    robot = load_robot("roarm_m2_s")
    rng = np.random.default_rng(1)
    for _ in range(100):
        q = rng.uniform(robot.lower[:3], robot.upper[:3])
        p = robot.kin.fk(robot.full_q(q))[:3, 3]
        sols = solve_ik(robot, p, all_solutions=True)
        assert min(np.max(np.abs(s[:3] - q)) for s in sols) < 1e-6
        for s in sols:
            assert np.linalg.norm(robot.kin.fk(s)[:3, 3] - p) < 1e-6
    with pytest.raises(Exception, match="position only"):
        solve_ik(robot, p, pitch=0.3)


def _plan(plan_path: Path):
    from roarmctl.motion.pipeline import plan_file

    return plan_file(plan_path)


def test_bundled_m2s_plans_its_example():
    res = _plan(ROOT / "plans" / "m2s_pick_place.yaml")
    traj = res.trajectory
    robot = load_robot("roarm_m2_s")
    assert traj.joint_names == robot.joint_names
    assert [e.kind for e in traj.events] == ["grasp", "release"]
    # the cube rests against the fixed jaw (its face 9.2 mm from the TCP, link3 z = +0.0092): its centre lies
    # 15 + 1 - 9.2 = 6.8 mm from the TCP along the face's normal; carried with the TCP it reaches the place
    jaw = robot.gripper.fixed_jaw
    (kg, kr) = (int(np.argmin(np.abs(traj.times - ev.time))) for ev in traj.events)
    tg, tr = robot.kin.fk(traj.positions[kg]), robot.kin.fk(traj.positions[kr])
    n = robot.kin.fk(traj.positions[kg], jaw.link)[:3, :3] @ np.asarray(jaw.normal)
    centre = np.array([0.22, -0.10, 0.015])
    assert np.allclose(centre - tg[:3, 3], 0.0068 * n, atol=5e-4)
    carried = tr[:3, :3] @ (tg[:3, :3].T @ (centre - tg[:3, 3])) + tr[:3, 3]
    assert np.linalg.norm(carried - [0.22, 0.10, 0.015]) < 2e-3


@needs_vendor
def test_moveit_package_with_meshes_plans_the_example(tmp_path):
    side = vendor_sidecar(tmp_path)
    plan = yaml.safe_load((ROOT / "plans" / "m2s_pick_place.yaml").read_text())
    plan["robot"] = str(side)
    (tmp_path / "plan.yaml").write_text(yaml.safe_dump(plan))
    traj = _plan(tmp_path / "plan.yaml").trajectory
    assert [e.kind for e in traj.events] == ["grasp", "release"]
    assert traj.duration > 1.0
