"""visualize-path and workspace: the plotted data against independent computations, PNG size, bad input.

The checks read the drawn artists' data (by gid) and compare it with values derived another way
(per-sample FK, finite differences, the closed-form singular values of the two-link arm), not pixels.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from roarmctl.errors import InputError, TrajectoryFileError
from roarmctl.motion.validate import load_trajectory
from roarmctl.robot.loader import load_robot

sys.path.insert(0, str(Path(__file__).parent))
import viz_fixtures  # noqa: E402

pytest.importorskip("matplotlib")
from matplotlib.image import imread  # noqa: E402

from roarmctl.viz.data import path_data, placed_objects, robot_for, workspace_data  # noqa: E402
from roarmctl.viz.path_figure import render_path, visualize_trajectory  # noqa: E402
from roarmctl.viz.workspace_figure import bin_max, render_workspace, workspace_maps  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PLANS = sorted((ROOT / "plans").glob("*.yaml"))


from clirun import roarmctl  # noqa: E402


@pytest.fixture(scope="module")
def pick_place():
    return viz_fixtures.pick_place_trajectory()


@pytest.fixture(scope="module")
def traj_file(tmp_path_factory, pick_place):
    path = tmp_path_factory.mktemp("viz") / "pick_place.traj.json"
    pick_place.save(path)
    return path


# The tests that read ``drawn`` share one xdist worker (mark ``DRAWN``): the sheet is drawn once (0.6-0.8 s of CPU),
# not on every worker that drew one of them.
DRAWN = pytest.mark.xdist_group("viz-drawn")


@pytest.fixture(scope="module")
def drawn(pick_place):
    data = path_data(pick_place, robot_for(pick_place))
    fig = render_path(data, view="iso", size=(12, 8))
    fig.canvas.draw()  # projects the 3D artists, as saving does
    return data, fig


def artists(fig, prefix: str) -> list:
    return [a for a in fig.findobj(lambda a: (a.get_gid() or "").startswith(prefix))]


# ----------------------------------------------------------------------------- the fixture itself
def test_fixture_reaches_its_targets_with_the_gripper_down(pick_place):
    robot = load_robot("roarm_m3_pro")
    for e in pick_place.events:
        i = int(np.argmin(np.abs(pick_place.times - e.time)))
        t = robot.kin.fk(pick_place.positions[i])
        assert np.allclose(t[:3, 3], e.position, atol=1e-6)
        assert t[2, 0] < -0.999  # approach axis (TCP x) points down
    assert robot.within_limits(pick_place.positions)


# ----------------------------------------------------------------------------- plotted data
@pytest.mark.slow
@DRAWN
def test_3d_path_is_fk_of_every_sample(pick_place, drawn):
    _data, fig = drawn
    robot = load_robot("roarm_m3_pro")
    (path,) = artists(fig, "tcp_path")
    segs = np.asarray(path._segments3d)
    expected = np.array([robot.kin.fk(q)[:3, 3] for q in pick_place.positions])  # one at a time, unbatched
    assert segs.shape == (len(expected) - 1, 2, 3)
    assert np.allclose(segs[:, 0], expected[:-1], atol=1e-12)
    assert np.allclose(segs[:, 1], expected[1:], atol=1e-12)


@pytest.mark.slow
@DRAWN
def test_cartesian_segments_are_drawn_thicker_and_straight(pick_place, drawn):
    data, fig = drawn
    (path,) = artists(fig, "tcp_path")
    widths = np.asarray(path.get_linewidths())
    cart = data.segment_kind == "cartesian"
    assert cart.any() and (~cart).any()
    assert widths[cart].min() > widths[~cart].max()
    # the thick pieces really are straight lines: every point of a Cartesian span on its chord
    for s in pick_place.segments:
        if s.kind != "cartesian":
            continue
        m = (data.times >= s.start - 1e-9) & (data.times <= s.end + 1e-9)
        p = data.tcp[m]
        chord = (p[-1] - p[0]) / np.linalg.norm(p[-1] - p[0])
        off = (p - p[0]) - np.outer((p - p[0]) @ chord, chord)
        assert np.abs(off).max() < 1e-6


@pytest.mark.slow
@DRAWN
def test_tcp_speed_agrees_with_finite_differences(drawn):
    data, _ = drawn
    fd = np.linalg.norm(np.gradient(data.tcp, data.times, axis=0), axis=1)
    assert np.abs(fd - data.tcp_speed)[1:-1].max() < 0.01 * data.tcp_speed.max() + 1e-4
    assert data.tcp_speed.max() <= 0.25 + 1e-9  # the fixture was timed to its max_tcp_speed


@pytest.mark.slow
@DRAWN
def test_limit_lines_sit_at_scale_times_limit(drawn):
    _data, fig = drawn
    robot = load_robot("roarm_m3_pro")
    for j, name in enumerate(robot.joint_names):
        for tag, lim in (("vlim", robot.velocity_limits[j] * 0.5), ("alim", robot.acceleration_limits[j] * 0.5)):
            ys = sorted(float(line.get_ydata()[0]) for line in artists(fig, f"{tag}:{name}"))
            assert ys == pytest.approx([-lim, lim])
    (mts,) = artists(fig, "max_tcp_speed")
    assert mts.get_ydata()[0] == pytest.approx(0.25)
    (margin,) = artists(fig, "singularity_margin")
    assert margin.get_ydata()[0] == pytest.approx(0.02)


@pytest.mark.slow
@DRAWN
def test_event_markers_at_event_times_in_every_time_plot(pick_place, drawn):
    _, fig = drawn
    for e in pick_place.events:
        lines = artists(fig, f"event:{e.kind}:")
        assert len(lines) == 6  # position, velocity, acceleration, torque, TCP speed, manipulability
        assert all(line.get_xdata()[0] == pytest.approx(e.time) for line in lines)
        (target,) = artists(fig, f"target:{e.kind}")
        assert np.allclose(np.ravel(target._offsets3d), e.position)


@DRAWN
def test_arm_drawn_at_start_each_event_and_end(pick_place, drawn):
    _data, fig = drawn
    robot = load_robot("roarm_m3_pro")
    arms = artists(fig, "arm:")
    assert [a.get_gid().split(":")[1] for a in arms] == ["start", "grasp", "release", "end"]
    times = [0.0] + [e.time for e in pick_place.events] + [pick_place.duration]
    for arm, t in zip(arms, times):
        i = int(np.argmin(np.abs(pick_place.times - t)))
        links = robot.kin.link_frames(pick_place.positions[i])[:, :3, 3]
        ends = np.asarray(arm._segments3d).reshape(-1, 3)
        # every drawn end is a link origin, and the TCP is among them
        assert all(np.min(np.linalg.norm(links - p, axis=1)) < 1e-12 for p in ends)
        assert np.min(np.linalg.norm(ends - links[robot.kin.tcp_index], axis=1)) < 1e-12


@pytest.mark.slow
@DRAWN
def test_placed_object_ghost_follows_the_grasp_offset(drawn):
    data, _ = drawn
    (ghost,) = data.placed_items
    assert ghost["xyz"] == pytest.approx(list(viz_fixtures.PLACE))
    assert ghost["size"] == [0.04, 0.04, 0.04]
    # no object near the grasp target: nothing is carried
    far = [dict(viz_fixtures.SCENE["items"][1], xyz=[0.0, 0.4, 0.02])]
    assert placed_objects(far, data.events) == []


def test_manipulability_of_the_two_link_arm_matches_closed_form():
    traj = viz_fixtures.planar_trajectory()
    data = path_data(traj, robot_for(traj))
    q2 = traj.positions[:, 1]
    c = np.cos(q2)
    # the minor radius of the 2R velocity ellipsoid (Mousavi Mohammadi & Akbarzadeh 2016, SCARA paper)
    # with l1 = l2 = 1 m, and w = l1 l2 |sin q2|
    r1 = np.sqrt(2) / 2 * np.sqrt(3 + 2 * c - np.sqrt(5 + 12 * c + 8 * c**2))
    assert np.allclose(data.sigma_min, r1, atol=1e-9)
    assert np.allclose(data.w, np.abs(np.sin(q2)), atol=1e-12)
    # the file has no limits block: the robot's own limits at scale 1
    robot = load_robot("planar_2r")
    assert data.limits_source == "robot"
    assert np.allclose(data.velocity_limit, robot.velocity_limits)


@pytest.mark.slow
def test_minimal_trajectory_renders(tmp_path):
    traj = viz_fixtures.planar_trajectory()
    out = visualize_trajectory(traj, tmp_path / "p.png", view="side", dpi=30, size=(10, 6))
    assert imread(out).shape[:2] == (180, 300)


# ----------------------------------------------------------------------------- CLI and PNG
@pytest.mark.slow
def test_cli_writes_png_of_requested_size(traj_file):
    proc = roarmctl("visualize-path", str(traj_file), "--dpi", "40", "--size", "12x8", "--view", "top")
    assert proc.returncode == 0, proc.stderr
    out = traj_file.with_name("pick_place.png")  # default: next to the file, same name
    img = imread(out)
    assert img.shape[:2] == (320, 480)
    assert img[..., :3].std() > 0.05  # not a blank sheet
    assert not list(traj_file.parent.glob(".*.tmp"))  # the atomic write left nothing behind


@pytest.mark.parametrize("view", ["iso", pytest.param("front", marks=pytest.mark.slow),
                                  pytest.param("side", marks=pytest.mark.slow)])  # make test-fast draws iso
def test_every_view_renders(tmp_path, pick_place, view):
    out = visualize_trajectory(pick_place, tmp_path / f"{view}.png", view=view, dpi=25, size=(16, 10))
    assert imread(out).shape[:2] == (250, 400)


def test_cli_bad_inputs_exit_2(tmp_path, traj_file):
    bad = tmp_path / "bad.traj.json"
    bad.write_text("{ not json")
    proc = roarmctl("visualize-path", str(bad))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "not valid JSON" in proc.stderr
    data = json.loads(traj_file.read_text())
    data["robot"] = "roarm_m9"
    other = tmp_path / "other.traj.json"
    other.write_text(json.dumps(data))
    proc = roarmctl("visualize-path", str(other))
    assert proc.returncode == 2 and "'roarm_m9', which is not installed" in proc.stderr
    assert not (tmp_path / "other.png").exists()


@pytest.mark.slow
def test_library_errors_are_input_errors(tmp_path, pick_place, traj_file):
    with pytest.raises(TrajectoryFileError):
        load_trajectory(tmp_path / "missing.traj.json")
    data = json.loads(traj_file.read_text())
    data["joint_names"] = [f"j{i}" for i in range(6)]
    p = tmp_path / "names.traj.json"
    p.write_text(json.dumps(data))
    with pytest.raises(TrajectoryFileError, match="do not match"):
        robot_for(load_trajectory(p))
    robot = load_robot("roarm_m3_pro")
    for field, value, match in [
        ("scene", {"items": [{"name": "x", "shape": "cone", "xyz": [0, 0, 0]}]}, "shape"),
        ("scene", {"items": [{"name": "x", "shape": "box", "size": [1, 2]}]}, "size"),
        ("limits", {"velocity": [1, 2]}, "limits.velocity"),
        ("limits", {"velocity_scale": -1}, "velocity_scale"),
        ("singularity_margin", {"min": 1}, "singularity_margin"),
    ]:
        t = load_trajectory(traj_file)
        setattr(t, field, value)
        with pytest.raises(InputError, match=match) as info:
            render_path(path_data(t, robot))
        assert info.value.exit_code == 2


def test_cli_option_errors_exit_2(traj_file):
    for args in (["--view", "below"], ["--size", "big"], ["--dpi", "5"], ["--size", "90x90", "--dpi", "300"]):
        proc = roarmctl("visualize-path", str(traj_file), *args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert proc.stderr.startswith("error: ")


@pytest.mark.parametrize("plan", [p if p.stem == "pick_place" else pytest.param(p, marks=pytest.mark.slow) for p in PLANS],
                         ids=[p.stem for p in PLANS])  # make test-fast draws pick_place; make test every plan (planned: CPU)
def test_bundled_plans_render(tmp_path, plan):
    from roarmctl.motion.pipeline import plan_file

    traj = plan_file(plan).trajectory
    data = path_data(traj, robot_for(traj))
    robot = load_robot(traj.robot)
    assert np.allclose(data.tcp, robot.kin.fk(traj.positions)[:, :3, 3])
    tasks = [e for e in traj.events if e.kind in ("grasp", "release")]
    assert len(data.events) == len(tasks) >= 2
    out = visualize_trajectory(traj, tmp_path / "plan.png", dpi=20, size=(16, 10))
    assert imread(out).shape[:2] == (200, 320)


@pytest.mark.slow
def test_cli_plans_a_yaml_first(tmp_path):
    src = PLANS[0] if PLANS else pytest.skip("no bundled plans")
    plan = tmp_path / src.name
    plan.write_text(src.read_text())
    proc = roarmctl("visualize-path", str(plan), "--dpi", "20")
    assert proc.returncode == 0, proc.stderr
    assert imread(plan.with_suffix(".png")).shape[:2] == (200, 320)


# ----------------------------------------------------------------------------- workspace
def test_bin_max_keeps_the_largest_value_per_cell():
    u = np.array([0.01, 0.02, 0.15, 0.35])
    v = np.array([0.01, 0.03, 0.01, 0.01])
    m = bin_max(u, v, np.array([1.0, 3.0, 2.0, 5.0]), cell=0.1)
    # origin at the smallest sample: cells x [0.01, 0.11) [0.11, 0.21) [0.21, 0.31) [0.31, 0.41)
    assert m.values.shape == (1, 4)
    assert m.values[0, 0] == 3.0 and m.values[0, 1] == 2.0 and np.isnan(m.values[0, 2]) and m.values[0, 3] == 5.0


def test_workspace_is_seeded_and_within_reach():
    robot = load_robot("roarm_m3_pro")
    a, b, c = workspace_data(robot, 2000, seed=3), workspace_data(robot, 2000, seed=3), workspace_data(robot, 2000, seed=4)
    assert np.array_equal(a.points, b.points) and not np.array_equal(a.points, c.points)
    assert np.all(a.q >= robot.lower) and np.all(a.q <= robot.upper)
    assert np.allclose(a.points, robot.kin.fk(a.q)[:, :3, 3])
    # the TCP never gets farther from the shoulder than the stretched arm
    shoulder = robot.kin.link_frames(robot.full_q(np.zeros(robot.arm_dof)))[robot.kin.link_index["link2"], :3, 3]
    stretched = robot.kin.link_frames(robot.full_q(np.array([0, 0, 0, 0, 0.0])))
    reach = sum(np.linalg.norm(stretched[b_, :3, 3] - stretched[a_, :3, 3]) for a_, b_ in
                [(robot.kin.link_index[x], robot.kin.link_index[y]) for x, y in
                 [("link2", "link3"), ("link3", "link4"), ("link4", "link5"), ("link5", "hand_tcp")]])
    assert np.linalg.norm(a.points - shoulder, axis=1).max() <= reach + 1e-9


def test_workspace_section_only_uses_samples_at_that_height():
    robot = load_robot("roarm_m3_pro")
    data = workspace_data(robot, 5000, seed=0)
    side, top, cell = workspace_maps(data, height=0.05)
    assert top.count == int(np.sum(np.abs(data.points[:, 2] - 0.05) <= cell))
    assert side.count == 5000


def test_workspace_negative_seed_is_an_input_error():
    """--seed -1 reached numpy's default_rng: an internal error (exit 1)."""
    r = roarmctl("workspace", "planar_2r", "--samples", "10", "--seed", "-1", "-o", "/nonexistent/ws.png")
    assert r.returncode == 2 and r.stderr.startswith("error: --seed: ") and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("height", [float("nan"), float("inf"), -1.0, 5.0])
def test_workspace_section_out_of_reach_or_not_finite_is_an_input_error(height):
    """--height nan, inf or out of reach drew an empty top map with exit 0."""
    from roarmctl.errors import InputError

    data = workspace_data(load_robot("roarm_m3_pro"), 2000, seed=0)
    with pytest.raises(InputError) as info:
        workspace_maps(data, height=height)
    assert info.value.option == "height"


@pytest.mark.slow
def test_workspace_cli(tmp_path):
    out = tmp_path / "ws.png"
    proc = roarmctl("workspace", "roarm_m3_pro", "-o", str(out), "--dpi", "50", "--samples", "20000")
    assert proc.returncode == 0, proc.stderr
    assert imread(out).shape[:2] == (300, 650)
    assert roarmctl("workspace", "no_such_robot", "-o", str(tmp_path / "x.png")).returncode == 2


def test_planar_arm_gets_one_map():
    fig = render_workspace(workspace_data(load_robot("planar_2r"), 3000, seed=0))
    assert len([a for a in fig.axes if a.images]) == 1


@pytest.mark.slow
def test_single_sample_trajectory_renders(tmp_path):
    robot = load_robot("roarm_m3_pro")
    q = robot.full_q(robot.named_poses["home"])[None]
    from roarmctl.motion.trajectory import Trajectory

    traj = Trajectory("roarm_m3_pro", list(robot.joint_names), np.array([0.0]), q, 0 * q, 0 * q)
    data = path_data(traj, robot)
    assert [k.kind for k in data.key_poses] == ["start", "end"]
    out = visualize_trajectory(traj, tmp_path / "one.png", dpi=20, size=(16, 10))
    assert imread(out).shape[:2] == (200, 320)


@pytest.mark.slow
def test_torque_panel_with_limits_and_blended_joins_marked():
    """The planned payload example: torque curves are RNEA with the held weight, each as a share of its own joint's
    limit (the M3's limits differ: 2.94 N m on the shoulder, 0.88 on the gripper) with one dashed limit at
    +-100 %, and every blended join is a dotted line in each time plot and a marker on the 3D path."""
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.robot.dynamics import inverse_dynamics
    from roarmctl.robot.model import Inertial

    traj = plan_file(ROOT / "plans" / "payload.yaml").trajectory
    robot = robot_for(traj)
    data = path_data(traj, robot)
    fig = render_path(data, view="iso", size=(12, 8))
    fig.canvas.draw()
    shoulder = "link1_to_link2"
    (line,) = artists(fig, f"tau:{shoulder}")
    grasp = next(e for e in traj.events if e.kind == "grasp").time
    k = int(np.searchsorted(traj.times, grasp)) + 5  # holding the weight
    (p,) = traj.payloads
    body = {p["link"]: Inertial(p["mass"], np.array(p["com"]), np.array(p["inertia"]))}
    assert p["mass"] == pytest.approx(0.2)
    expect = inverse_dynamics(robot, traj.positions[k], traj.velocities[k], traj.accelerations[k], payload=body)
    assert line.get_ydata()[k] == pytest.approx(100 * expect[robot.joint_index(shoulder)] / 2.94, abs=1e-7)
    assert sorted(a.get_ydata()[0] for a in artists(fig, "taulim")) == pytest.approx([-100.0, 100.0])
    # every joint's curve peaks at its own peak torque over its own limit, whatever the others' limits
    from roarmctl.motion.report import joint_torques

    tau = joint_torques(traj, robot)
    for j, name in enumerate(traj.joint_names):
        (curve,) = artists(fig, f"tau:{name}")
        peak = np.max(np.abs(tau[:, j])) / robot.effort_limits[j] * 100
        assert np.max(np.abs(curve.get_ydata())) == pytest.approx(peak, rel=1e-9)
    assert traj.blends
    for name in ("q", "v", "a", "torque", "speed", "manip"):
        xs = sorted(a.get_xdata()[0] for a in artists(fig, f"blend:{name}"))
        assert xs == pytest.approx(sorted(traj.blends))
    assert len(artists(fig, "blend3d")) == 1
