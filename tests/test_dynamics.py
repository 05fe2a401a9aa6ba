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
