"""Recursive Newton-Euler against the closed-form Lagrange model of the two-link arm and the UR10 numbers
of the course report that robots/ur10.yaml comes from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roarmctl.errors import DescriptionError
from roarmctl.robot.dynamics import coriolis_vector, gravity_vector, inverse_dynamics, mass_matrix
from roarmctl.robot.loader import load_robot

G = 9.81
P2R = load_robot("planar_2r")


def lagrange_2r(q, qd, m1=1.0, m2=1.0, l1=1.0, l2=1.0, g=G):
    """D, C, G of the textbook two-link arm (point masses at the link ends), written out by hand."""
    c1, c2, c12, s2 = math.cos(q[0]), math.cos(q[1]), math.cos(q[0] + q[1]), math.sin(q[1])
    d = np.array([[(m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2, m2 * l2**2 + m2 * l1 * l2 * c2],
                  [m2 * l2**2 + m2 * l1 * l2 * c2, m2 * l2**2]])
    h = -m2 * l1 * l2 * s2
    c = np.array([[h * qd[1], h * (qd[0] + qd[1])], [-h * qd[0], 0.0]])
    gv = np.array([(m1 + m2) * g * l1 * c1 + m2 * g * l2 * c12, m2 * g * l2 * c12])
    return d, c, gv


def test_seed001_numeric_checks():
    assert np.allclose(mass_matrix(P2R, [0, 0]), [[5, 2], [2, 1]], atol=1e-12)
    assert np.allclose(gravity_vector(P2R, [0, 0]), [29.43, 9.81], atol=1e-12)
    q, qd = [math.pi / 4, math.pi / 3], [1.0, -0.5]
    assert np.allclose(mass_matrix(P2R, q), [[4, 1.5], [1.5, 1]], atol=1e-12)
    assert np.allclose(coriolis_vector(P2R, q, qd), [0.649519, 0.866025], atol=1e-6)
    assert np.allclose(gravity_vector(P2R, q), [11.33442, -2.539015], atol=1e-5)


def test_rnea_matches_lagrange_at_random_states():
    rng = np.random.default_rng(0)
    for _ in range(200):
        q, qd, qdd = rng.uniform(-math.pi, math.pi, 2), rng.uniform(-3, 3, 2), rng.uniform(-5, 5, 2)
        d, c, gv = lagrange_2r(q, qd)
        assert np.allclose(inverse_dynamics(P2R, q, qd, qdd), d @ qdd + c @ qd + gv, atol=1e-10)
        assert np.allclose(mass_matrix(P2R, q), d, atol=1e-12)


def test_hanging_equilibrium_needs_no_torque():
    assert np.allclose(gravity_vector(P2R, [-math.pi / 2, 0]), 0, atol=1e-12)


@pytest.mark.parametrize("name", ["planar_2r", "ur10", "roarm_m3_pro"])
def test_mass_matrix_spd_and_consistent(name):
    r = load_robot(name)
    rng = np.random.default_rng(1)
    lo, hi = r.lower, r.upper
    for _ in range(20):
        q = rng.uniform(np.maximum(lo, -3), np.minimum(hi, 3))
        m = mass_matrix(r, q)
        assert np.allclose(m, m.T, atol=1e-12)
        assert np.linalg.eigvalsh(m).min() > 0
        qd, qdd = rng.uniform(-1, 1, r.dof), rng.uniform(-1, 1, r.dof)
        tau = inverse_dynamics(r, q, qd, qdd)
        assert np.allclose(tau, m @ qdd + coriolis_vector(r, q, qd) + gravity_vector(r, q), atol=1e-9)


@pytest.mark.parametrize("name", ["planar_2r", "ur10", "roarm_m3_pro"])
def test_gravity_is_gradient_of_potential_energy(name):
    """G = dV/dq with V = sum m g z_com: a different method than RNEA (finite differences of FK)."""
    r = load_robot(name)
    rng = np.random.default_rng(2)

    def potential(q):
        frames = r.kin.link_frames(q)
        v = 0.0
        for link, inn in r.inertials.items():
            f = frames[r.kin.link_index[link]]
            v += inn.mass * G * (f[:3, :3] @ inn.com + f[:3, 3])[2]
        return v

    for _ in range(5):
        q = rng.uniform(np.maximum(r.lower, -3), np.minimum(r.upper, 3))
        h = 1e-6
        num = np.array([(potential(q + h * e) - potential(q - h * e)) / (2 * h) for e in np.eye(r.dof)])
        assert np.allclose(gravity_vector(r, q), num, atol=1e-6)


def test_kinetic_energy_matches_mass_matrix():
    """0.5 qd^T M qd equals the sum of link kinetic energies from finite-difference link velocities."""
    r = load_robot("ur10")
    rng = np.random.default_rng(3)
    q, qd = rng.uniform(-2, 2, 6), rng.uniform(-1, 1, 6)
    h = 1e-6
    f0, f1 = r.kin.link_frames(q - h * qd), r.kin.link_frames(q + h * qd)
    ke = 0.0
    for link, inn in r.inertials.items():
        k = r.kin.link_index[link]
        c0 = f0[k, :3, :3] @ inn.com + f0[k, :3, 3]
        c1 = f1[k, :3, :3] @ inn.com + f1[k, :3, 3]
        v = (c1 - c0) / (2 * h)
        rdot = (f1[k, :3, :3] - f0[k, :3, :3]) / (2 * h)
        rot = r.kin.link_frames(q)[k, :3, :3]
        wx = rdot @ rot.T
        w = np.array([wx[2, 1], wx[0, 2], wx[1, 0]])
        iw = rot @ inn.inertia @ rot.T
        ke += 0.5 * inn.mass * v @ v + 0.5 * w @ iw @ w
    assert 0.5 * qd @ mass_matrix(r, q) @ qd == pytest.approx(ke, rel=1e-6)


def test_ur10_seed003_metre_com_reproduction():
    """M(0) and G(0) as the UR10 course report computed them with its own Lagrange model (COMs of links 1-3
    in metres; d4 = 0.16389 m there, 0.1639 m here: 1e-3 relative slack)."""
    u = load_robot("ur10")
    m0 = mass_matrix(u, np.zeros(6))
    for (i, j), v in {(0, 0): 19.8114, (1, 1): 18.9676, (1, 2): 6.37986, (2, 2): 2.84951, (0, 4): 0.0140356}.items():
        assert m0[i, j] == pytest.approx(v, rel=1e-3)
    assert np.allclose(gravity_vector(u, np.zeros(6)), [0, 215.945, 56.506, 0, 0, 0], atol=0.01)
    assert np.allclose(coriolis_vector(u, np.zeros(6), [1, 0, 0, 0, 0, 0]),
                       [0, 0.33397, 0.33397, 0.33397, -0.060761, 0.00048387], atol=1e-4)
    assert np.allclose(gravity_vector(u, np.full(6, math.pi / 4)), [0, 110.535, -2.20518, -2.20518, 0.253028, 0.000587], atol=2e-3)
    assert np.allclose(gravity_vector(u, np.full(6, math.pi / 2)), [0, -53.7443, -53.7443, 2.76193, -0.0040074, 0], atol=2e-3)
    m45 = mass_matrix(u, np.full(6, math.pi / 4))
    for (i, j), v in {(0, 0): 5.27048, (0, 1): -1.84569, (1, 1): 16.3569, (1, 2): 4.97590, (2, 2): 2.65231}.items():
        assert m45[i, j] == pytest.approx(v, rel=1e-3)


def test_roarm_gravity_signs():
    r = load_robot("roarm_m3_pro")
    g = gravity_vector(r, r.named_poses["home"])
    assert g.shape == (6,)
    # arm stretched forward: gravity tips it forward (+shoulder), so holding needs a negative torque
    assert g[1] < -0.05 and g[2] < 0
    assert g[0] == pytest.approx(0.0, abs=1e-12)  # the base axis is vertical
    up = gravity_vector(r, np.zeros(6))  # upright: only the 30 mm elbow offset and COM offsets load it
    assert abs(up[1]) < 0.3 * abs(g[1])


def test_arm_only_vectors_accepted():
    r = load_robot("roarm_m3_pro")
    a = inverse_dynamics(r, [0, 0.2, 1.0, 0.1, 0], [0.1] * 5, [0.2] * 5)
    b = inverse_dynamics(r, [0, 0.2, 1.0, 0.1, 0, 0], [0.1] * 5 + [0], [0.2] * 5 + [0])
    assert np.allclose(a, b)


def test_missing_inertials_named():
    with pytest.raises(DescriptionError) as ei:
        gravity_vector(load_robot("scara_2r"), [0, 0])
    assert "link1" in str(ei.value) and "inertial" in str(ei.value)


def test_batched_rnea_equals_one_state_at_a_time():
    r = load_robot("roarm_m3_pro")
    rng = np.random.default_rng(4)
    q = rng.uniform(np.maximum(r.lower, -3), np.minimum(r.upper, 3), size=(7, r.dof))
    qd, qdd = rng.uniform(-2, 2, size=(7, r.dof)), rng.uniform(-5, 5, size=(7, r.dof))
    batch = inverse_dynamics(r, q, qd, qdd)
    assert batch.shape == (7, r.dof)
    for k in range(7):
        assert np.allclose(batch[k], inverse_dynamics(r, q[k], qd[k], qdd[k]), atol=1e-12)


def test_payload_point_mass_adds_its_weight_times_lever_arm():
    """A point mass m on the 2R tip at q = 0 adds m g (l1 + l2) at joint 1 and m g l2 at joint 2 (hand-derived)."""
    from roarmctl.robot.model import Inertial

    tip = P2R.kin.link_names[-1]
    m = 0.7
    body = {tip: Inertial(m, np.zeros(3), np.zeros((3, 3)))}
    # the tip frame's origin: where FK puts it
    extra = inverse_dynamics(P2R, [0, 0], [0, 0], [0, 0], payload=body) - gravity_vector(P2R, [0, 0])
    reach = np.linalg.norm(P2R.kin.link_frames(np.zeros(2))[P2R.kin.link_index[tip], :2, 3])
    l2 = reach - 1.0
    assert np.allclose(extra, [m * G * reach, m * G * l2], atol=1e-9)


# A tree with the joint kinds no bundled robot with inertials has: a prismatic lift, revolute joints about x
# and about a tilted axis, a fixed tool, and a mimic finger (multiplier -1) on a side branch; every link has
# an off-centre, rotated body.
_BODY = """<inertial><origin xyz="{c}" rpy="0.3 -0.2 0.5"/><mass value="{m}"/>
  <inertia ixx="{i}" ixy="0.0004" ixz="-0.0003" iyy="{j}" iyz="0.0002" izz="{k}"/></inertial>"""
ODD_URDF = f"""<robot name="odd">
  <link name="base">{_BODY.format(c="0 0 0.05", m=2.0, i=0.01, j=0.012, k=0.009)}</link>
  <link name="slide">{_BODY.format(c="0.01 0 0.1", m=0.8, i=0.004, j=0.005, k=0.003)}</link>
  <link name="arm">{_BODY.format(c="0 0.1 0.01", m=0.5, i=0.002, j=0.001, k=0.0025)}</link>
  <link name="hand">{_BODY.format(c="0.01 0 0.03", m=0.3, i=0.0015, j=0.0012, k=0.001)}</link>
  <link name="tip">{_BODY.format(c="0 0.01 0.01", m=0.1, i=0.0008, j=0.0007, k=0.0006)}</link>
  <link name="finger">{_BODY.format(c="0 0 0.02", m=0.05, i=0.0005, j=0.0006, k=0.0004)}</link>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="slide"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
  <joint name="pitch" type="revolute"><parent link="slide"/><child link="arm"/><origin xyz="0 0 0.2" rpy="0 0 0.3"/>
    <axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="twist" type="revolute"><parent link="arm"/><child link="hand"/><origin xyz="0 0.2 0" rpy="0.2 0 0"/>
    <axis xyz="0 0.6 0.8"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="hand"/><child link="tip"/><origin xyz="0 0 0.06" rpy="0 0.4 0"/></joint>
  <joint name="finger_joint" type="revolute"><parent link="hand"/><child link="finger"/><origin xyz="0.02 0 0.05"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="twist" multiplier="-1" offset="0.2"/></joint>
</robot>
"""


def _lagrange_torque(robot, q, qd, qdd, payload=None, g=G):
    """tau = M qdd + (dM/dt) qd - 1/2 d(qd^T M qd)/dq + dV/dq (Euler-Lagrange) with M = sum over bodies of
    m Jp^T Jp + Jw^T (R I R^T) Jw, every Jacobian and derivative by central differences of the FK: a method
    independent of the Newton-Euler recursion. ``payload`` bodies are added as separate bodies."""
    bodies = [(robot.kin.link_index[n], b) for n, b in robot.inertials.items()]
    bodies += [(robot.kin.link_index[n], b) for n, b in (payload or {}).items()]
    dof = robot.dof

    def com_and_rot(qq):
        f = robot.kin.link_frames(qq)
        return [(f[k, :3, :3] @ b.com + f[k, :3, 3], f[k, :3, :3]) for k, b in bodies]

    def mass(qq, h=1e-5):
        plus = [com_and_rot(qq + h * e) for e in np.eye(dof)]
        minus = [com_and_rot(qq - h * e) for e in np.eye(dof)]
        rots = com_and_rot(qq)
        m = np.zeros((dof, dof))
        for b, (_k, body) in enumerate(bodies):
            jp = np.stack([(plus[i][b][0] - minus[i][b][0]) / (2 * h) for i in range(dof)], axis=1)
            jw = []
            for i in range(dof):
                wx = (plus[i][b][1] - minus[i][b][1]) / (2 * h) @ rots[b][1].T
                jw.append([wx[2, 1], wx[0, 2], wx[1, 0]])
            jw = np.array(jw).T
            r = rots[b][1]
            m += body.mass * jp.T @ jp + jw.T @ (r @ body.inertia @ r.T) @ jw
        return m

    def potential(qq):
        return sum(body.mass * g * c[2] for (k, body), (c, _) in zip(bodies, com_and_rot(qq)))

    eps = 1e-4
    mdot = (mass(q + eps * qd) - mass(q - eps * qd)) / (2 * eps)
    dke = np.array([qd @ (mass(q + eps * e) - mass(q - eps * e)) @ qd / (2 * eps) for e in np.eye(dof)])
    dv = np.array([(potential(q + eps * e) - potential(q - eps * e)) / (2 * eps) for e in np.eye(dof)])
    return mass(q) @ qdd + mdot @ qd - 0.5 * dke + dv


@pytest.mark.parametrize("name", ["odd", "ur10", "roarm_m3_pro"])
def test_rnea_equals_euler_lagrange_by_finite_differences(name, tmp_path):
    """Newton-Euler torques equal Euler-Lagrange torques from finite differences of the FK, on a tree with a
    prismatic joint, tilted and x axes, a fixed tool and a mimic finger (its share adds to the joint it
    follows), on the DH UR10 (every joint with a post) and on the RoArm with a held payload."""
    from roarmctl.robot.model import Inertial

    if name == "odd":
        path = tmp_path / "odd.urdf"
        path.write_text(ODD_URDF)
        r = load_robot(str(path))
    else:
        r = load_robot(name)
    payload = None
    if name == "roarm_m3_pro":
        payload = {r.tcp_link: Inertial(0.2, np.array([0.01, -0.005, 0.02]), np.diag([2e-4, 3e-4, 1e-4]))}
    rng = np.random.default_rng(5)
    for _ in range(3):
        q = rng.uniform(np.maximum(r.lower, -2), np.minimum(r.upper, 2))
        qd, qdd = rng.uniform(-1.5, 1.5, r.dof), rng.uniform(-3, 3, r.dof)
        tau = inverse_dynamics(r, q, qd, qdd, payload=payload)
        ref = _lagrange_torque(r, q, qd, qdd, payload)
        np.testing.assert_allclose(tau, ref, atol=1e-6 * max(1.0, np.abs(ref).max()), rtol=0)
        # at rest: the holding torques alone (the kernel's at-rest shortcut)
        rest = inverse_dynamics(r, q, np.zeros(r.dof), np.zeros(r.dof), payload=payload)
        np.testing.assert_allclose(rest, _lagrange_torque(r, q, np.zeros(r.dof), np.zeros(r.dof), payload),
                                   atol=1e-6 * max(1.0, np.abs(rest).max()), rtol=0)
