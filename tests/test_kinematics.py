"""Forward kinematics against hand-derived values and published worked examples; Jacobian against FK."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roarmctl.robot.loader import load_robot

ROARM = load_robot("roarm_m3_pro")
UR10 = load_robot("ur10")
P2R = load_robot("planar_2r")
SCARA = load_robot("scara_2r")
ALL = [ROARM, UR10, P2R, SCARA]

Z_SHOULDER = 0.0701 + 0.051959  # world -> base_link, base_link -> shoulder axis (URDF)


def roarm_by_hand(q) -> np.ndarray:
    """TCP position of the RoArm from the URDF numbers, as a planar arm turned by the base angle.

    In the arm's plane, angles from vertical (positive forward): upper arm 0.236815 along and
    0.030002 across, turned by the shoulder s; forearm 0.144586 along, turned by s + e; TCP 0.169081
    along (0.053653 + 0.115428) and 0.015147 across from the wrist axis, turned by s + e + w.
    """
    b, s, e, w = q[:4]

    def seg(along, across, ang):
        return np.array([along * math.sin(ang) + across * math.cos(ang), along * math.cos(ang) - across * math.sin(ang)])

    r, z = seg(0.236815, 0.030002, s) + seg(0.144586, 0.0, s + e) + seg(0.053653 + 0.115428, 0.015147, s + e + w)
    return np.array([r * math.cos(b), r * math.sin(b), Z_SHOULDER + z])


# ---------------------------------------------------------------------------------- RoArm
def test_roarm_zero_pose_points_up():
    """Waveshare's roarm_m3.xacro with all joints 0: the arm points straight up (origins summed by hand)."""
    f = ROARM.kin.link_frames(np.zeros(6))
    at = lambda name: f[ROARM.kin.link_index[name], :3, 3]  # noqa: E731
    assert np.allclose(at("link2"), [0, 0, 0.122059], atol=1e-6)
    assert np.allclose(at("link3"), [0.030001, 0, 0.288774 + 0.0701], atol=1e-6)
    assert np.allclose(at("link4"), [0.030001, 0, 0.433360 + 0.0701], atol=1e-6)
    assert np.allclose(at("hand_tcp"), [0.045148, 0, 0.672541], atol=1e-6)
    rot = f[ROARM.kin.tcp_index, :3, :3]
    assert np.allclose(rot, [[0, 0, -1], [0, 1, 0], [1, 0, 0]], atol=1e-5)  # approach axis +x_tcp points up


def test_roarm_named_poses():
    home = ROARM.kin.fk(ROARM.named_poses["home"])
    assert np.allclose(home[:3, 3], [0.343668, 0, 0.273628 + 0.0701], atol=2e-6)
    assert np.allclose(home[:3, :3], np.eye(3), atol=1e-5)  # approach axis horizontal, along +x
    assert np.allclose(ROARM.kin.fk(ROARM.named_poses["ready"])[:3, 3], [0.27137, 0, 0.14841 + 0.0701], atol=1e-5)
    assert np.allclose(ROARM.kin.fk(ROARM.named_poses["observe"])[:3, 3], [0.15944, 0, 0.11969 + 0.0701], atol=1e-5)


def test_roarm_fk_by_hand_random():
    """The URDF writes pi/2 as 1.5708 (3.7 urad off), so the hand model agrees to a few micrometres."""
    rng = np.random.default_rng(0)
    for q in rng.uniform(ROARM.lower, ROARM.upper, size=(200, 6)):
        assert np.linalg.norm(ROARM.kin.fk(q)[:3, 3] - roarm_by_hand(q)) < 5e-6


def test_roarm_roll_and_gripper_do_not_move_tcp():
    q = np.array([0.3, 0.4, 1.0, 0.5, 0.0, 0.0])
    p0 = ROARM.kin.fk(q)[:3, 3]
    for roll, grip in [(1.0, 0.0), (-2.0, 1.2)]:
        q2 = q.copy()
        q2[4], q2[5] = roll, grip
        assert np.allclose(ROARM.kin.fk(q2)[:3, 3], p0, atol=1e-6)


def firmware_fk_mm(q) -> np.ndarray:
    """The firmware's FK, RoArmM3_computePosbyJointRad (Waveshare RoArm-M3 example firmware 0.84,
    RoArm-M3_module.h, lengths from RoArm-M3_config.h), z measured from the shoulder axis (mm)."""
    b, s, e, w = q[:4]
    l2a, l2b, l3, l4a, l4b = 236.82, 30.00, 144.49, 171.67, 13.69
    l2, t2 = math.hypot(l2a, l2b), math.atan2(l2b, l2a)
    le, te = math.hypot(l4a, l4b), math.atan2(l4b, l4a)
    r = l2 * math.sin(s + t2) + l3 * math.sin(e + s) + le * math.sin(e + s + w + te)
    z = l2 * math.cos(s + t2) + l3 * math.cos(e + s) + le * math.cos(e + s + w + te)
    return np.array([r * math.cos(b), r * math.sin(b), z])


def test_roarm_fk_matches_firmware_within_3mm():
    """Our URDF FK vs the firmware's own FK formula over the whole joint range: worst 3.02 mm.

    The two do not define the same TCP: in the wrist frame the firmware's point is 171.67 mm along and
    13.69 mm across (the "edge" gripper constants), the URDF's hand_tcp 169.081 mm along and
    15.147 mm across, 2.97 mm apart; the forearm is 144.49 mm vs 144.586 mm (0.1 mm). The worst case
    is where both add up, hence the bound of 3.05 mm (the issue asks for 3 mm "within the workspace").
    Signs agree (the identity mapping roarm-sdk uses for the arm joints), which is what this test guards.
    """
    assert math.hypot(171.67 - 169.081, 13.69 - 15.147) == pytest.approx(2.97, abs=0.01)
    grids = [np.linspace(ROARM.lower[i], ROARM.upper[i], n) for i, n in ((1, 13), (2, 13), (3, 13))]
    s, e, w = (g.ravel() for g in np.meshgrid(*grids, indexing="ij"))
    b = np.linspace(-3.0, 3.0, s.size)
    qs = np.zeros((s.size, 6))
    qs[:, 0], qs[:, 1], qs[:, 2], qs[:, 3] = b, s, e, w
    ours = ROARM.kin.fk(qs)[:, :3, 3] * 1000.0
    ours[:, 2] -= Z_SHOULDER * 1000.0
    worst = max(np.linalg.norm(o - firmware_fk_mm(q)) for o, q in zip(ours, qs))
    assert 2.9 < worst <= 3.05
    # spot checks at home (mm, relative to the shoulder axis): URDF hand_tcp, and the firmware's own
    # init pose x = l2B + l3A + l4A = 346.16, z = l2A - l4B = 223.13 (RoArm-M3_config.h)
    home = ROARM.kin.fk([0, 0, math.pi / 2, 0, 0])[:3, 3] * 1000 - [0, 0, Z_SHOULDER * 1000]
    assert np.allclose(home, [343.67, 0, 221.67], atol=0.01)
    assert np.allclose(firmware_fk_mm([0, 0, math.pi / 2, 0]), [346.16, 0, 223.13], atol=0.01)


# ---------------------------------------------------------------------------------- 2R arms
def test_planar_2r_by_hand():
    rng = np.random.default_rng(1)
    for q in rng.uniform(-math.pi, math.pi, size=(50, 2)):
        c1, s1, c12, s12 = math.cos(q[0]), math.sin(q[0]), math.cos(q.sum()), math.sin(q.sum())
        # vertical x-z plane: theta1 from +x toward +z (up)
        assert np.allclose(P2R.kin.fk(q)[:3, 3], [c1 + c12, 0, s1 + s12], atol=1e-12)
        assert np.allclose(P2R.kin.fk(q, "link1")[:3, 3], [c1, 0, s1], atol=1e-12)


def test_scara_by_hand():
    q = np.radians([30.0, -45.0])
    assert np.allclose(SCARA.kin.fk(q)[:3, 3],
                       [0.4 * math.cos(q[0]) + 0.3 * math.cos(q.sum()), 0.4 * math.sin(q[0]) + 0.3 * math.sin(q.sum()), 0],
                       atol=1e-12)
    assert np.allclose(SCARA.lower, np.radians([-110, -130])) and np.allclose(SCARA.upper, np.radians([110, 130]))


# ---------------------------------------------------------------------------------- UR10
UR10_CASES = {  # the course report's worked FK examples, mm
    (0, 0, 0, 0, 0, 0): ([[1, 0, 0], [0, 0, -1], [0, 1, 0]], [1184.5, -256.1, 243.7]),
    (45, 90, 0, -90, 0, 60): ([[0.3535534, -0.6123724, 0.7071068], [0.3535534, -0.6123724, -0.7071068], [0.8660254, 0.5, 0]],
                              [181.0900467, -181.0900467, 1428.2]),
    (30, 45, 26, 50, 60, 80): ([[-0.8449696, 0.5171601, -0.1362786], [-0.3141952, -0.6862252, -0.6560307],
                                [-0.4327907, -0.5115079, 0.7423287]], [519.9835444, 57.7255263, 1110.6969610]),
    (60,) * 6: (None, [152.2666, -156.2666, 1038.1071]),
    (45,) * 6: ([[-0.957107, 0.25, 0.146447], [-0.25, -0.457107, -0.853553], [-0.146447, -0.853553, 0.5]],
                [377.9972, 54.0076, 1097.2735]),
    (90,) * 6: ([[0, 1, 0], [1, 0, 0], [0, 0, -1]], [163.9, -455.9, 648.7]),
}


@pytest.mark.parametrize("qdeg", list(UR10_CASES))
def test_ur10_worked_examples(qdeg):
    rot, pos = UR10_CASES[qdeg]
    t = UR10.kin.fk(np.radians(qdeg))
    assert np.allclose(t[:3, 3] * 1000, pos, atol=0.1)  # 0.1 mm
    if rot is not None:
        assert np.allclose(t[:3, :3], rot, atol=1e-6)


# ---------------------------------------------------------------------------------- batching
@pytest.mark.parametrize("robot", ALL, ids=lambda r: r.name)
def test_batched_fk_equals_loop(robot):
    rng = np.random.default_rng(2)
    qs = rng.uniform(np.maximum(robot.lower, -3), np.minimum(robot.upper, 3), size=(64, robot.dof))
    batch = robot.kin.link_frames(qs)
    loop = np.stack([robot.kin.link_frames(q) for q in qs])
    assert batch.shape == (64, len(robot.link_names), 4, 4)
    # the same numbers bit for bit whatever the batch size (one compiled FK, no size-dependent path)
    assert np.array_equal(batch, loop)
    assert np.array_equal(robot.kin.jacobian(qs), np.stack([robot.kin.jacobian(q) for q in qs]))


# ---------------------------------------------------------------------------------- Jacobian
def numeric_jacobian(robot, q, h=1e-6):
    q = robot.full_q(q)
    cols = []
    for i in robot.arm_indices:
        dq = np.zeros(robot.dof)
        dq[i] = h
        tp, tm = robot.kin.fk(q + dq), robot.kin.fk(q - dq)
        v = (tp[:3, 3] - tm[:3, 3]) / (2 * h)
        wx = (tp[:3, :3] - tm[:3, :3]) / (2 * h) @ robot.kin.fk(q)[:3, :3].T
        cols.append(np.concatenate([v, [wx[2, 1], wx[0, 2], wx[1, 0]]]))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("robot", ALL, ids=lambda r: r.name)
def test_jacobian_matches_finite_differences(robot):
    rng = np.random.default_rng(3)
    for q in rng.uniform(np.maximum(robot.lower, -3), np.minimum(robot.upper, 3), size=(20, robot.dof)):
        jac = robot.kin.jacobian(q)
        assert jac.shape == (6, robot.arm_dof)
        assert np.allclose(jac, numeric_jacobian(robot, q), atol=1e-8)


def test_ur10_det_j_formula_seed_1_9():
    a2, a3, d5 = 0.6129, 0.5716, 0.1157
    rng = np.random.default_rng(4)
    for q in list(rng.uniform(-math.pi, math.pi, size=(20, 6))) + [np.radians([30, 45, 26, 50, 60, 80])]:
        c2, c23, s234 = math.cos(q[1]), math.cos(q[1] + q[2]), math.sin(q[1] + q[2] + q[3])
        expected = a2 * a3 * (a2 * c2 + a3 * c23 - d5 * s234) * math.sin(q[2]) * math.sin(q[4])
        assert np.linalg.det(UR10.kin.jacobian(q)) == pytest.approx(expected, abs=1e-12)
    assert np.linalg.det(UR10.kin.jacobian(np.radians([30, 45, 26, 50, 60, 80]))) == pytest.approx(0.0692012, abs=1e-7)
    assert np.linalg.det(UR10.kin.jacobian(np.radians([45] * 6))) == pytest.approx(6.1584011e7 * 1e-9, rel=1e-6)


def test_scara_ellipsoid_at_stretched_singularity_seed_004():
    m = SCARA.kin.manipulability([0.0, 0.0])
    assert np.allclose(m.ellipsoid_radii, [0.761577, 0.0], atol=1e-6)
    assert m.translational == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(np.abs(m.ellipsoid_axes[:, 0]), [0, 1, 0], atol=1e-9)  # the major axis is along y
    # away from it, r1 r2 = |det J| = l1 l2 |sin theta2| (Mousavi Mohammadi & Akbarzadeh 2016, eqs 6-15)
    m = SCARA.kin.manipulability([0.3, 1.1])
    assert np.prod(m.ellipsoid_radii) == pytest.approx(0.4 * 0.3 * abs(math.sin(1.1)), rel=1e-9)


# ------------------------------------------------------------- the one FK vs a naive chain product
def naive_link_frames(robot, q: np.ndarray) -> np.ndarray:
    """Reference FK for a full q (dof,), or a batch of them (N, dof): each joint as origin @ motion(q) @ post, full
    4x4 products, rotations from scipy-free Rodrigues written out here (a different method from the library's
    cos/sin-linear steps and constant-link folding). (L, 4, 4) per q, (N, L, 4, 4) for a batch."""
    q = np.asarray(q, dtype=float)
    qs = np.atleast_2d(q)
    n = len(qs)
    names = robot.link_names
    frames = {names[0]: np.broadcast_to(np.eye(4), (n, 4, 4))}
    for joint in robot.joints:
        motion = np.repeat(np.eye(4)[None], n, axis=0)
        # a mimic joint moves with the joint it follows: multiplier * q + offset (URDF <mimic>)
        qi = robot.joint_names.index(joint.mimic or joint.name) if joint.kind != "fixed" else None
        if joint.kind == "revolute":
            k = np.asarray(joint.axis, dtype=float)
            kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            ang = joint.multiplier * qs[:, qi] + joint.offset
            motion[:, :3, :3] = np.eye(3) + np.sin(ang)[:, None, None] * kx + (1 - np.cos(ang))[:, None, None] * (kx @ kx)
        elif joint.kind == "prismatic":
            motion[:, :3, 3] = (joint.multiplier * qs[:, qi] + joint.offset)[:, None] * np.asarray(joint.axis, dtype=float)
        frames[joint.child] = frames[joint.parent] @ joint.origin @ motion @ joint.post
    out = np.stack([frames[nm] for nm in names], axis=1)
    return out[0] if q.ndim == 1 else out


@pytest.mark.parametrize("robot", ALL, ids=lambda r: r.name)
def test_fk_equals_a_naive_chain_product(robot):
    q = np.random.default_rng(1).uniform(robot.lower, robot.upper, (32, robot.dof))
    ref = np.array([naive_link_frames(robot, qi) for qi in q])
    np.testing.assert_allclose(naive_link_frames(robot, q), ref, atol=1e-12, rtol=0)  # the reference batched, too
    np.testing.assert_allclose(robot.kin.link_frames(q), ref, atol=1e-12, rtol=0)  # batched
    for qi, ri in zip(q[:8], ref[:8]):
        np.testing.assert_allclose(robot.kin.link_frames(qi), ri, atol=1e-12, rtol=0)  # one configuration


def test_jacobian_and_tcp_velocity_of_prismatic_and_tilted_joints_match_finite_differences(tmp_path):
    """A chain with a prismatic lift, an x-axis joint and a tilted axis (plus a mimic finger off the chain):
    the Jacobian equals central differences of the FK, and tcp_velocity(q, qd) equals the TCP's
    finite-difference velocity along qd, batched as one at a time."""
    from test_checkkernel import ODD_URDF

    path = tmp_path / "odd.urdf"
    path.write_text(ODD_URDF)
    robot = load_robot(str(path))
    assert {j.kind for j in robot.joints} == {"prismatic", "revolute", "fixed"}
    rng = np.random.default_rng(6)
    q = rng.uniform(robot.lower, robot.upper, (16, robot.dof))
    qd = rng.uniform(-1, 1, (16, robot.arm_dof))
    h = 1e-6
    for qi, vi in zip(q, qd):
        assert np.allclose(robot.kin.jacobian(qi), numeric_jacobian(robot, qi), atol=1e-8)
        step = np.zeros(robot.dof)
        step[robot.arm_indices] = h * vi
        v = (robot.kin.fk(qi + step)[:3, 3] - robot.kin.fk(qi - step)[:3, 3]) / (2 * h)
        np.testing.assert_allclose(robot.kin.tcp_velocity(qi, vi)[0], v, atol=1e-8)
    np.testing.assert_array_equal(robot.kin.tcp_velocity(q, qd),
                                  np.concatenate([robot.kin.tcp_velocity(qi, vi) for qi, vi in zip(q, qd)]))


def test_a_robot_survives_pickling_and_deep_copy():
    """A robot can be sent to another process (pickle) or deep-copied, and its FK, Jacobian and dynamics work
    there with the same numbers."""
    import copy
    import pickle

    from roarmctl.robot.dynamics import inverse_dynamics

    q = np.random.default_rng(7).uniform(ROARM.lower, ROARM.upper, (4, ROARM.dof))
    for other in (pickle.loads(pickle.dumps(ROARM)), copy.deepcopy(ROARM)):
        assert np.array_equal(other.kin.link_frames(q), ROARM.kin.link_frames(q))
        assert np.array_equal(other.kin.jacobian(q), ROARM.kin.jacobian(q))
        assert np.array_equal(inverse_dynamics(other, q, q, q), inverse_dynamics(ROARM, q, q, q))


def test_quaternions_agree_with_scipy_on_every_branch_of_shepperds_method():
    """``robot.model.quaternions`` (what the ROS export and the MuJoCo model write) against scipy's Rotation, on
    random rotations and on half-turns about x, y and z (each takes another of the method's four formulas)."""
    from scipy.spatial.transform import Rotation

    from roarmctl.robot.model import quaternions

    rots = list(Rotation.random(200, random_state=7).as_matrix())
    rots += [Rotation.from_rotvec(np.pi * np.array(a) + 1e-3 * np.array(b)).as_matrix()
             for a, b in [((1, 0, 0), (0, 1, 0)), ((0, 1, 0), (1, 0, 0)), ((0, 0, 1), (1, 0, 0))]]
    got = quaternions(np.array(rots).reshape(-1, 3, 3))
    ref = Rotation.from_matrix(rots).as_quat()  # x, y, z, w
    ref[ref[:, 3] < 0] *= -1
    np.testing.assert_allclose(got, ref, atol=1e-12)
    assert quaternions(np.array(rots[:6]).reshape(2, 3, 3, 3)).shape == (2, 3, 4)
    np.testing.assert_allclose(quaternions(np.eye(3)), [0, 0, 0, 1])


def test_rigid_inverse_is_the_matrix_inverse():
    from scipy.spatial.transform import Rotation

    from roarmctl.robot.model import rigid_inverse

    t = np.tile(np.eye(4), (5, 1, 1))
    t[:, :3, :3] = Rotation.random(5, random_state=3).as_matrix()
    t[:, :3, 3] = np.random.default_rng(3).normal(size=(5, 3))
    np.testing.assert_allclose(rigid_inverse(t), np.linalg.inv(t), atol=1e-12)
