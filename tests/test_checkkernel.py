"""The compiled kernel (src/roarmctl/_kernel.c) against independent answers: its FK (the library's one FK) against
a naive chain product, its margin measure against the SVD of a finite-difference Jacobian, its
separating-axis filter and its candidate pairs against FCL."""

from __future__ import annotations

import fcl
import numpy as np
import pytest

from roarmctl import _kernel as kernel
from roarmctl.motion.collision import CollisionChecker, interpolate
from roarmctl.motion.scene import Scene, SceneItem, example_scene
from roarmctl.robot.loader import bundled_robots, load_robot
from roarmctl.robot.model import transform

# A small arm with the joint kinds no bundled robot has: a prismatic lift, a revolute joint about x, a mimic joint.
ODD_URDF = """<robot name="odd">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="slide"><collision><origin xyz="0 0 0.1"/><geometry><box size="0.04 0.04 0.2"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0 0.1 0"/><geometry><box size="0.03 0.2 0.03"/></geometry></collision></link>
  <link name="hand"><collision><origin xyz="0 0 0.03"/><geometry><cylinder radius="0.02" length="0.06"/></geometry></collision></link>
  <link name="tip"/>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="slide"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
  <joint name="pitch" type="revolute"><parent link="slide"/><child link="arm"/><origin xyz="0 0 0.2" rpy="0 0 0.3"/>
    <axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="twist" type="revolute"><parent link="arm"/><child link="hand"/><origin xyz="0 0.2 0"/>
    <axis xyz="0 0.6 0.8"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="hand"/><child link="tip"/><origin xyz="0 0 0.06"/></joint>
  <link name="finger"><collision><origin xyz="0 0 0.02"/><geometry><box size="0.01 0.01 0.04"/></geometry></collision></link>
  <joint name="finger_joint" type="revolute"><parent link="hand"/><child link="finger"/><origin xyz="0.02 0 0.05"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="twist" multiplier="-1" offset="0.2"/></joint>
</robot>
"""


def robots(tmp_path_factory) -> list:
    odd = tmp_path_factory.mktemp("odd") / "odd.urdf"
    odd.write_text(ODD_URDF)
    return [load_robot(name) for name in bundled_robots()] + [load_robot(str(odd))]


def _step_kinds(kin) -> set[int]:
    """Kind codes of the kinematic table's steps (src/roarmctl/_kernel.c: 0 fixed, 1 z rotation, 2 other axis,
    3 prismatic, plus 4 for a step with a DH post)."""
    n_steps, n_const = int(kin._ki[2]), int(kin._ki[3])
    steps = kin._ki[7 + n_const:7 + n_const + 5 * n_steps].reshape(-1, 5)
    return set(steps[:, 0].tolist()) | ({4} if steps[:, 4].any() else set())


def test_kernel_fk_and_margin_measure_against_independent_answers(tmp_path_factory):
    """Every link frame of the kernel's FK (Kinematics.frames4, as the checker's tables hold it) equals a
    naive chain product origin @ motion(q) @ post (z rotation, other-axis revolute, prismatic, fixed, DH
    post, mimic), gripper values included; the margin measure equals the smallest singular value of a
    central-difference Jacobian of the naive FK."""
    from test_kinematics import naive_link_frames

    kinds = set()
    for robot in robots(tmp_path_factory):
        kinds |= _step_kinds(robot.kin)
        checker = CollisionChecker(robot, Scene([]), singularity_margin=0.01)
        rng = np.random.default_rng(2)
        q = rng.uniform(checker._lower, checker._upper, (24, robot.arm_dof))
        grip = None
        full = checker._full(q)
        if robot.gripper is not None:
            g = robot.joint_index(robot.gripper.joint)
            grip = rng.uniform(robot.lower[g], robot.upper[g], 24)
            full[:, g] = grip
        ref = np.array([naive_link_frames(robot, qi) for qi in full])
        np.testing.assert_allclose(robot.kin.frames4(full), ref, atol=1e-12, rtol=0, err_msg=robot.name)
        h = 1e-6
        tcp = robot.kin.tcp_index
        num = np.zeros((len(full), 3, robot.arm_dof))
        for c, i in enumerate(robot.arm_indices):
            for k, qi in enumerate(full):
                dq = np.zeros(robot.dof)
                dq[i] = h
                num[k, :, c] = (naive_link_frames(robot, qi + dq)[tcp, :3, 3]
                                - naive_link_frames(robot, qi - dq)[tcp, :3, 3]) / (2 * h)
        sv = np.linalg.svd(num, compute_uv=False)[:, -1]
        np.testing.assert_allclose(checker.margin_measure(q, grip), sv, atol=1e-8, err_msg=robot.name)
    assert kinds == {0, 1, 2, 3, 4}


def _random_rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.slow
def test_separating_axis_never_clears_boxes_that_fcl_finds_touching():
    """4000 random box pairs around the touching distance (a third of them with parallel or shared axes):
    whenever the kernel's separating-axis test calls them apart, FCL finds no contact; and it clears most
    of the pairs FCL finds apart (it is exact up to its 1e-9 m tolerance for boxes)."""
    rng = np.random.default_rng(5)
    cleared = apart_fcl = 0
    for k in range(4000):
        ra = _random_rotation(rng)
        rb = ra.copy() if k % 3 == 0 else _random_rotation(rng)  # parallel edges: the degenerate cross axes
        if k % 3 == 1:
            rb = ra @ transform((0, 0, 0), (0, 0, rng.uniform(-np.pi, np.pi)))[:3, :3]  # one shared axis
        ha, hb = rng.uniform(0.005, 0.08, 3), rng.uniform(0.005, 0.08, 3)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        cb = direction * rng.uniform(0.0, np.linalg.norm(ha) + np.linalg.norm(hb))
        ca = np.zeros(3)
        a = fcl.CollisionObject(fcl.Box(*(2 * ha)), fcl.Transform(ra, ca))
        b = fcl.CollisionObject(fcl.Box(*(2 * hb)), fcl.Transform(rb, cb))
        touching = fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0
        apart = kernel.apart(np.ascontiguousarray(ra), ca, ha, np.ascontiguousarray(rb), cb, hb)
        assert not (apart and touching), (ra, ca, ha, rb, cb, hb)
        cleared += apart
        apart_fcl += not touching
    assert apart_fcl > 1000 and cleared >= 0.99 * apart_fcl


def _hold_a_box(checker: CollisionChecker) -> None:
    """Attach a 3 x 3 x 5 cm box held 3 cm below the TCP at a fixed arm pose, as a grasped object."""
    q0 = np.array([0.0, 0.4, 1.6, 0.5, 0.0])
    held = SceneItem.box("held", (0.03, 0.03, 0.05), checker.tcp_pose(q0)[:3, 3] + [0, 0, -0.03])
    checker.add_item(held)
    checker.set_grasp_target("held")
    checker.attach("held", q0)


@pytest.mark.slow
@pytest.mark.parametrize("attached", [False, True])
def test_pairs_the_kernel_clears_are_apart_for_fcl(attached):
    """On 1500 random RoArm states in the example scene (padding 5 mm, with and without a held box), every
    (shape, item) and (shape, shape) pair that the kernel does not hand to FCL is apart for FCL too."""
    robot = load_robot("roarm_m3_pro")
    checker = CollisionChecker(robot, example_scene(), padding=0.005)
    if attached:
        _hold_a_box(checker)
    rng = np.random.default_rng(7)
    q = rng.uniform(checker._lower, checker._upper, (1500, robot.arm_dof))
    b = checker._buffers(len(q))
    ns, npairs, _ = kernel.check(checker._kf, checker._ki, q, np.zeros(0), b["valid"], b["near"], b["scene"], b["self"],
                                 b["pose"], 0.0, False)
    scene_c = {tuple(r) for r in b["scene"][:ns].tolist()}
    self_c = {tuple(r) for r in b["self"][:npairs].tolist()}
    moving = checker._moving_shapes
    frames = robot.kin.frames4(checker._full(q))  # shape poses by the library's FK, not the kernel's
    hits = {"scene": 0, "self": 0}
    checked = 0
    for i in np.flatnonzero(b["valid"][:len(q)]):
        for mv in moving:
            link = frames[i, mv.link]
            for obj in (mv.obj_scene, mv.obj_self):
                obj.setRotation(link[:3, :3] @ mv.rot)
                obj.setTranslation(link[:3, 3] + link[:3, :3] @ mv.pos)
        for a in range(len(moving)):
            for k, item in enumerate(checker._item_objs):
                if checker._scene_mask[a, k] and (i, a, k) not in scene_c:
                    checked += 1
                    assert not fcl.collide(moving[a].obj_scene, item), (i, a, k)
                hits["scene"] += (i, a, k) in scene_c and fcl.collide(moving[a].obj_scene, item) > 0
        for p, (a, c) in enumerate(checker._pairs):
            if (i, p) not in self_c:
                checked += 1
                assert not fcl.collide(moving[a].obj_self, moving[c].obj_self), (i, a, c)
            hits["self"] += (i, p) in self_c and fcl.collide(moving[a].obj_self, moving[c].obj_self) > 0
    assert checked > 10000 and hits["scene"] > 0 and hits["self"] > 0  # both kinds of candidates occur


@pytest.mark.parametrize("name", ["ur10", "roarm_m3_pro", "planar_2r"])
def test_margin_decisions_equal_the_margin_measure(name):
    """The kernel decides the margin by a closed form away from the boundary and by the Jacobi measure near
    it: its decisions equal margin_measure(q) >= margin, with margins at quantiles of the measure (many
    states within a hair of the boundary) and at measured values exactly."""
    robot = load_robot(name)
    plain = CollisionChecker(robot, Scene([]))
    q = np.random.default_rng(11).uniform(plain._lower, plain._upper, (5000, robot.arm_dof))
    free = plain.validity_batch(q)  # self-collision and limits, without a margin
    sig = CollisionChecker(robot, Scene([]), singularity_margin=0.01).margin_measure(q)
    for margin in [*np.quantile(sig, [0.05, 0.3, 0.6]), sig[17], sig[99]]:
        checker = CollisionChecker(robot, Scene([]), singularity_margin=float(margin))
        np.testing.assert_array_equal(checker.validity_batch(q), free & (sig >= margin))


def test_segment_states_made_by_the_kernel_are_interpolates_states():
    """segment_valid without refinement (the kernel makes the states) answers as validity_batch of
    interpolate()'s states, on 600 random segments around the example scene's obstacles, at two resolutions."""
    from roarmctl.motion.collision import interpolate

    robot = load_robot("roarm_m3_pro")
    checker = CollisionChecker(robot, example_scene(), singularity_margin=0.02)
    rng = np.random.default_rng(8)
    q = rng.uniform(checker._lower, checker._upper, (600, robot.arm_dof))
    answers = set()
    for q0 in q:
        q1 = q0 + rng.normal(size=robot.arm_dof) * rng.choice([0.05, 0.3, 1.0])
        for res in (0.01, 0.07):
            expected = bool(checker.validity_batch(interpolate(q0, q1, res)).all())
            assert checker.segment_valid(q0, q1, res, refine=1) is expected
            answers.add(expected)
    assert answers == {True, False}


def test_checks_from_two_threads_answer_as_one_thread():
    """OMPL's PRM calls the checker from two threads: with a tiny GIL switch interval, two threads checking
    different segments and states at once get the answers a single thread gets (shared kernel buffers and
    FCL objects are used one check at a time)."""
    import sys
    import threading

    robot = load_robot("roarm_m3_pro")
    checker = CollisionChecker(robot, example_scene(), singularity_margin=0.02)
    rng = np.random.default_rng(9)
    q = rng.uniform(checker._lower, checker._upper, (1500, robot.arm_dof))
    segs = [(a, a + rng.normal(size=robot.arm_dof) * 0.4) for a in q[:300]] * 2
    expected_seg = [checker.segment_valid(a, b) for a, b in segs]
    expected_one = [checker.is_valid(x) for x in q[300:]] * 2
    got: dict[str, list] = {}

    def run_segments():
        got["seg"] = [checker.segment_valid(a, b) for a, b in segs]

    def run_states():
        got["one"] = [checker.is_valid(x) for x in q[300:]] + [checker.is_valid(x) for x in q[300:]]

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        threads = [threading.Thread(target=run_segments), threading.Thread(target=run_states)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(old)
    assert got["seg"] == expected_seg and got["one"] == expected_one
    assert 0 < sum(expected_seg) < len(segs) and 0 < sum(expected_one) < len(expected_one)



def _near_scene_checker(attached: bool) -> CollisionChecker:
    """The example scene plus a tilted slab and a cylinder post (no margin: FCL and the limits decide alone),
    optionally holding a box."""
    robot = load_robot("roarm_m3_pro")
    scene = example_scene()
    scene.items.append(SceneItem.box("slab", (0.03, 0.16, 0.2), (0.05, 0.24, 0.1), rpy=(0.0, 0.0, 0.6)))
    scene.items.append(SceneItem.cylinder("post", 0.03, 0.4, (0.2, -0.22, 0.2)))
    checker = CollisionChecker(robot, scene, padding=0.005)
    if attached:
        _hold_a_box(checker)
    return checker


def _sphere_slack(checker: CollisionChecker, q: np.ndarray) -> np.ndarray:
    """(N, S, M) m: distance from each shape's bounding sphere to each item's world box (what the kernel's sphere
    test measures), by the library's FK; inf for the pairs the checker skips."""
    frames = checker.robot.kin.frames4(checker._full(q))[:, checker._mv_link]
    centres = frames[:, :, :3, 3] + np.einsum("nsij,sj->nsi", frames[:, :, :3, :3], checker._mv_pos)
    lo, hi = checker._item_lo[None, None], checker._item_hi[None, None]
    gap = np.linalg.norm(np.maximum(np.maximum(lo - centres[:, :, None], centres[:, :, None] - hi), 0.0), axis=3)
    return np.where(checker._scene_mask[None], gap - checker._mv_radius[None, :, None], np.inf)


def _states_near_items(checker: CollisionChecker, seed: int, n: int) -> np.ndarray:
    """n valid random states (n, arm_dof) where some shape's bounding sphere is within 3 cm of an item's box."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(checker._lower, checker._upper, (40 * n, checker._lower.size))
    # the first n of the draws that qualify, in the draws' order: judged a chunk at a time until n are found (the same
    # states as judging all 40 n draws, without the slack of the tens of thousands never used)
    found: list[np.ndarray] = []
    for c in range(0, len(q), 2048):
        chunk = q[c:c + 2048]
        chunk = chunk[checker.validity_batch(chunk)]
        found.append(chunk[_sphere_slack(checker, chunk).min(axis=(1, 2)) < 0.03])
        if sum(map(len, found)) >= n:
            break
    q = np.concatenate(found)
    assert len(q) >= n
    return q[:n]


@pytest.mark.slow
@pytest.mark.parametrize("attached", [False, True])
def test_a_state_that_is_not_near_is_clear_for_its_whole_sweep(attached):
    """The "near" flag is what segment_valid's proof rests on: a state not near at sweep s (m) must stay valid for
    FCL at every state within s / sweep_gain (rad) of it, since no arm point moves farther than s there. On 1500
    random states close to the scene's items: every (shape, item) pair of a not-near state is more than s apart
    (FCL's distance), 8 states at that joint distance (random directions) and 8 at half of it per not-near state
    are all valid, and the shapes' grown boxes clear many states whose grown bounding spheres (the test before)
    were near."""
    checker = _near_scene_checker(attached)
    q = _states_near_items(checker, 11, 1500)
    rng = np.random.default_rng(13)
    slack = _sphere_slack(checker, q)
    frames = checker.robot.kin.frames4(checker._full(q))  # shape poses by the library's FK, not the kernel's
    checked = box_cleared = pairs = 0
    for sweep in (0.003, 0.01, 0.03):
        b = checker._buffers(len(q))
        kernel.check(checker._kf, checker._ki, q, np.zeros(0), b["valid"], b["near"], b["scene"], b["self"], b["pose"],
                     sweep, False)
        near = b["near"][:len(q)].astype(bool)
        sphere_near = (slack < sweep - 1e-9).any(axis=(1, 2))
        box_cleared += int((sphere_near & ~near).sum())
        for i, a, k in zip(*np.nonzero(~near[:, None, None] & (slack < sweep))):  # the pairs only the box test clears
            mv, frame = checker._moving_shapes[a], frames[i, checker._mv_link[a]]
            mv.obj_scene.setRotation(frame[:3, :3] @ mv.rot)
            mv.obj_scene.setTranslation(frame[:3, 3] + frame[:3, :3] @ mv.pos)
            result = fcl.DistanceResult()
            gap = fcl.distance(mv.obj_scene, checker._item_objs[k], fcl.DistanceRequest(), result)
            assert gap > sweep - 1e-7, (sweep, gap, i, a, k)  # no point that moves <= sweep can reach the item
            pairs += 1
        free = q[~near]
        d = rng.normal(size=(len(free), 16, q.shape[1]))
        d /= np.linalg.norm(d, axis=2)[:, :, None]
        d[:, 8:] *= 0.5
        moved = np.clip(free[:, None] + d * (sweep / checker.sweep_gain), checker._lower, checker._upper)
        ok = checker.validity_batch(moved.reshape(-1, q.shape[1]))
        assert ok.all(), moved.reshape(-1, q.shape[1])[~ok][:3]
        checked += ok.size
    assert checked > 20000 and box_cleared > 300 and pairs > 300, (checked, box_cleared, pairs)


@pytest.mark.slow
@pytest.mark.parametrize("attached", [False, True])
def test_valid_segments_have_no_colliding_state_at_eight_times_the_resolution(attached):
    """segment_valid's verdict against a dense re-check (validity_batch, FCL on every candidate) of 1500 random
    short segments from states close to the scene's items: no segment it passes has an invalid state at 1/8 of
    its resolution."""
    checker = _near_scene_checker(attached)
    q = _states_near_items(checker, 12, 1500)
    rng = np.random.default_rng(14)
    d = rng.normal(size=q.shape)
    d *= rng.uniform(0.05, 0.6, (len(q), 1)) / np.linalg.norm(d, axis=1)[:, None]
    passed = 0
    for q0, q1 in zip(q, np.clip(q + d, checker._lower, checker._upper)):
        if checker.segment_valid(q0, q1, 0.01):
            passed += 1
            assert checker.validity_batch(interpolate(q0, q1, 0.01 / 8)).all(), (q0, q1)
    assert 300 < passed < 1450, passed


def test_a_full_pass_that_skips_the_coarse_states_keeps_their_flags():
    """check_line's skip: after a coarse call (every 8th state, with the sweep), the full pass that skips those states
    leaves the same near flags on every row as a full pass that checks them all, and segment_valid answers as its
    states checked one by one (validity_batch) where no state is near, on 300 long random segments."""
    checker = _near_scene_checker(False)
    rng = np.random.default_rng(15)
    q = _states_near_items(checker, 16, 300)
    d = rng.normal(size=q.shape)
    d *= rng.uniform(0.4, 1.2, (len(q), 1)) / np.linalg.norm(d, axis=1)[:, None]
    compared = near = 0
    for q0, q1 in zip(q, np.clip(q + d, checker._lower, checker._upper)):
        dq = np.ascontiguousarray(q1 - q0)
        steps = int(np.ceil(np.linalg.norm(dq) / 0.01))
        if steps < 32:
            continue
        b = checker._buffers(steps + 1)
        views = b["views"]

        def line(start, stride, skip, q0=q0, dq=dq, steps=steps, b=b, views=views):
            kernel.check_line(checker._kf, checker._ki, q0, dq, steps, start, stride, np.zeros(0, dtype=np.int64), 1,
                              *views, 0.004, False, skip)
            return b["valid"][:steps + 1].copy(), b["near"][:steps + 1].copy()

        valid_all, near_all = line(0, 1, 0)
        line(8, 8, 0)
        valid_skip, near_skip = line(0, 1, 8)
        np.testing.assert_array_equal(near_skip, near_all)
        coarse = np.arange(8, steps + 1, 8)
        assert valid_skip[coarse].all()  # skipped: they count as valid (the coarse call decided them)
        np.testing.assert_array_equal(np.delete(valid_skip, coarse), np.delete(valid_all, coarse))
        compared += 1
        near += int(near_all.sum())
        assert checker.segment_valid(q0, q1, 0.01, refine=1) == bool(checker.validity_batch(interpolate(q0, q1, 0.01)).all())
    assert compared > 200 and near > 100, (compared, near)


@pytest.mark.parametrize("attached", [False, True])
def test_a_segment_at_the_set_gripper_value_checks_as_its_states_with_the_gripper_given_per_state(attached):
    """check_line makes the gripper step's matrix once per call (the gripper stays at its set value); ``check`` with
    the gripper value given per state makes it at every state. On 150 segments from states near the items, at three
    gripper values (open, half, closed), both give the same verdicts, near flags, candidate pairs and candidate
    poses (bit for bit), with the margin on; the answers differ between the open and the closed gripper."""
    checker = _near_scene_checker(attached)
    checker.singularity_margin = 0.02
    checker._pack()
    grip = checker.robot.gripper
    rng = np.random.default_rng(21)
    q = _states_near_items(checker, 22, 150)
    d = rng.normal(size=q.shape)
    d *= rng.uniform(0.05, 0.5, (len(q), 1)) / np.linalg.norm(d, axis=1)[:, None]
    answers: dict[float, list] = {}
    candidates = 0
    for g in (grip.open, 0.5 * (grip.open + grip.closed), grip.closed):
        checker.set_gripper(g)
        answers[g] = []
        for q0, q1 in zip(q, np.clip(q + d, checker._lower, checker._upper)):
            dq = np.ascontiguousarray(q1 - q0)
            states = interpolate(q0, q1, 0.01)
            n = len(states)
            out = []
            for per_state in (False, True):
                b = checker._buffers(n)
                if per_state:
                    r = kernel.check(checker._kf, checker._ki, states, np.full(n, g), *b["views"], 0.004, False)
                else:
                    r = kernel.check_line(checker._kf, checker._ki, q0, dq, n - 1, 0, 1, np.zeros(0, dtype=np.int64), 1,
                                          *b["views"], 0.004, False, 0)[:3]
                sc, pc = b["scene"][:r[0]].copy(), b["self"][:r[1]].copy()
                poses = [b["pose"][i, a].copy() for i, a, _ in sc]
                poses += [b["pose"][i, a].copy() for i, p in pc for a in checker._pairs[p]]
                out.append((r, b["valid"][:n].copy(), b["near"][:n].copy(), sc, pc, poses))
            (r1, v1, n1, s1, p1, P1), (r2, v2, n2, s2, p2, P2) = out
            assert r1 == r2
            for x, y in ((v1, v2), (n1, n2), (s1, s2), (p1, p2)):
                np.testing.assert_array_equal(x, y)
            for x, y in zip(P1, P2):
                np.testing.assert_array_equal(x, y)
            candidates += len(s1) + len(p1)
            answers[g].append((v1.tobytes(), n1.tobytes(), s1.tobytes(), p1.tobytes()))
    assert candidates > 500, candidates
    assert answers[grip.open] != answers[grip.closed]  # the gripper value matters to these states


@pytest.mark.parametrize("attached", [False, True])
def test_segment_valid_in_one_kernel_call_answers_as_its_passes_made_in_python(attached):
    """segment_valid runs its passes (every 8th state, the others, the refinement next to near states) in one kernel
    call (_kernel.segment), back in Python only for FCL; on 600 random segments of 0.01-1 rad from states near the
    items (margin on), at resolutions 0.005-0.02 and refine 1-4, its verdicts and its count of checked states equal
    those of the same passes made one by one from Python (``_passes``, with steps and sweep from numpy)."""
    checker = _near_scene_checker(attached)
    checker.singularity_margin = 0.02
    checker._pack()
    rng = np.random.default_rng(31)
    q = _states_near_items(checker, 32, 600)
    d = rng.normal(size=q.shape)
    d *= rng.uniform(0.01, 1.0, (len(q), 1)) / np.linalg.norm(d, axis=1)[:, None]
    verdicts = {True: 0, False: 0}
    for q0, q1 in zip(q, q + d):
        resolution, refine = float(rng.choice([0.005, 0.01, 0.02])), int(rng.choice([1, 4, 4, 3]))
        c0 = checker.check_count
        got = checker.segment_valid(q0, q1, resolution, refine)
        got_count = checker.check_count - c0
        dq = q1 - q0
        steps = max(1, int(np.ceil(np.sqrt(dq.dot(dq)) / resolution)))
        e = (q0 + dq * (1.0 / steps)) - q0
        sweep = 0.5 * float(np.sqrt(e.dot(e))) * checker.sweep_gain
        c0 = checker.check_count
        want = checker._passes(q0, dq, steps, sweep, refine, 0)
        assert (got, got_count) == (want, checker.check_count - c0)
        verdicts[got] += 1
    assert verdicts[True] > 100 and verdicts[False] > 100, verdicts
