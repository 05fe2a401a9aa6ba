"""``roarmctl export``: the demo trajectory and its execution log as MCAP, a ROS 2 bag folder and CSV,
read back with rosbags (and the MCAP container with the independent ``mcap`` reader)."""

from __future__ import annotations

import csv
import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from clirun import virtual_simulator

from roarmctl.cli import run as run_cli

# the demo run on the simulated arm (real time) is exported; the module on one xdist worker, so the run is made once
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("export-demo")]

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "plans" / "pick_place.yaml"
PLACE_XYZ = (0.25, 0.15, 0.02)  # plans/pick_place.yaml: where the cube's centre goes
CUBE_SIZE = (0.04, 0.04, 0.04)




@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The `make demo` commands: plan the bundled pick-and-place and run it on the simulator (with ideal servos:
    these tests are about what export makes of a log, not about how the arm follows, tests/device's subject)."""
    d = tmp_path_factory.mktemp("demo")
    traj, log = d / "pick_place.traj.json", d / "pick_place.exec.json"
    assert run_cli(["plan", str(PLAN), "-o", str(traj), "--json"]) == 0
    with virtual_simulator():  # on a virtual clock: what a run logs, not its real time (tests/device's subject)
        assert run_cli(["execute", str(traj), "--sim", "--servos", "ideal", "--yes", "--json", "--log", str(log)]) == 0
    return d, traj, log


@functools.cache
def _jazzy():
    """rosbags' ROS 2 Jazzy types, once per worker (each typestore compiles its deserialisers on first use)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def read_bag(path: Path) -> dict[str, list]:
    """topic -> [(log time ns, msgtype, message)] read with rosbags."""
    from rosbags.rosbag2 import Reader

    ts = _jazzy()
    out: dict[str, list] = {}
    with Reader(path) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, conn.msgtype, ts.deserialize_cdr(raw, conn.msgtype)))
    return out


def quat_matrix(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def tf_matrix(tr) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_matrix(tr.transform.rotation)
    m[:3, 3] = [tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z]
    return m


def chain_to(link: str, transforms: dict[str, tuple[str, np.ndarray]]) -> np.ndarray:
    """Compose TF edges (child -> (parent, parent_T_child)) from the tree root to ``link``."""
    m = np.eye(4)
    while link in transforms:
        parent, t = transforms[link]
        m = t @ m
        link = parent
    return m


def check_plan_bag(bag: dict[str, list], traj_path: Path) -> None:
    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot

    traj = load_trajectory(traj_path)
    robot = load_robot(traj.robot)
    n = len(traj.times)
    types = {topic: {m[1] for m in msgs} for topic, msgs in bag.items()}
    assert types == {
        "/joint_trajectory": {"trajectory_msgs/msg/JointTrajectory"},
        "/joint_states": {"sensor_msgs/msg/JointState"},
        "/tf": {"tf2_msgs/msg/TFMessage"},
        "/tf_static": {"tf2_msgs/msg/TFMessage"},
        "/scene": {"visualization_msgs/msg/MarkerArray"},
    }
    # the JointTrajectory carries every point with the file's values
    (_, _, jt), = bag["/joint_trajectory"]
    assert jt.joint_names == traj.joint_names and len(jt.points) == n
    for i in (0, n // 2, n - 1):
        p = jt.points[i]
        assert p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 == pytest.approx(traj.times[i], abs=1e-9)
        assert np.allclose(p.positions, traj.positions[i]) and np.allclose(p.velocities, traj.velocities[i])
        assert np.allclose(p.accelerations, traj.accelerations[i])
    # one JointState per sample (100 Hz), stamped at the sample time
    js = bag["/joint_states"]
    assert len(js) == n
    t = np.array([m[0] for m in js]) * 1e-9
    assert np.allclose(t, traj.times, atol=1e-9) and np.all(np.diff(t) <= 0.01 + 1e-9)  # segments end exactly: some steps are shorter
    assert np.allclose(np.array([m[2].position for m in js]), traj.positions)
    assert all(m[2].header.stamp.sec + m[2].header.stamp.nanosec * 1e-9 == pytest.approx(m[0] * 1e-9, abs=1e-9) for m in js)
    # TF: composing the published edges gives the TCP that FK gives (independent: quaternions here)
    static = {tr.child_frame_id: (tr.header.frame_id, tf_matrix(tr)) for tr in bag["/tf_static"][0][2].transforms}
    assert len(bag["/tf"]) == n
    fk = robot.kin.fk(traj.positions)
    for i in (0, n // 3, n - 1):
        edges = dict(static)
        edges.update({tr.child_frame_id: (tr.header.frame_id, tf_matrix(tr)) for tr in bag["/tf"][i][2].transforms})
        assert set(edges) == set(robot.link_names[1:])
        assert np.allclose(chain_to(robot.tcp_link, edges), fk[i], atol=1e-9)
    # scene: table as planned; the cube rides with the hand and ends where the plan places it
    scene = bag["/scene"]
    first = {m.text: m for m in scene[0][2].markers}
    assert set(first) == {"table", "cube"} and scene[0][0] == 0
    table = first["table"]
    assert (table.type, table.scale.x, table.scale.y, table.scale.z) == (1, 0.8, 0.6, 0.02)  # CUBE, plan's size
    cube_end = {m.text: m for m in scene[-1][2].markers}["cube"]
    assert (cube_end.scale.x, cube_end.scale.y, cube_end.scale.z) == CUBE_SIZE
    end = cube_end.pose.position
    assert math.dist((end.x, end.y, end.z), PLACE_XYZ) < 0.002
    grasp, release = [e.time for e in traj.events]
    moving = [m[0] * 1e-9 for m in scene[1:]]
    assert min(moving) > grasp and max(moving) == pytest.approx(release, abs=0.011)
    assert len(scene) == 1 + np.count_nonzero((traj.times > grasp + 1e-9) & (traj.times <= release + 0.01 - 1e-9))
    # while carried, the cube keeps its offset to the TCP
    mid = scene[len(scene) // 2]
    k = int(np.argmin(np.abs(traj.times - mid[0] * 1e-9)))
    c = {m.text: m for m in mid[2].markers}["cube"].pose.position
    off = np.array([c.x, c.y, c.z]) - fk[k, :3, 3]
    c1 = {m.text: m for m in scene[1][2].markers}["cube"].pose.position
    k1 = int(np.argmin(np.abs(traj.times - scene[1][0] * 1e-9)))
    assert np.allclose(off, np.array([c1.x, c1.y, c1.z]) - fk[k1, :3, 3], atol=0.01)


def test_demo_trajectory_as_mcap_is_foxglove_ready(demo, capsys):
    d, traj, _ = demo
    out = d / "pick_place.mcap"
    assert run_cli(["export", str(traj), "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["ok"] and summary["format"] == "mcap"
    check_plan_bag(read_bag(out), traj)
    from mcap.reader import make_reader

    with out.open("rb") as f:  # the container as Foxglove sees it: ros2 profile, ros2msg schemas, CDR
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        s = reader.get_summary()
        assert {sc.encoding for sc in s.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in s.channels.values()} == {"cdr"}
        counts = {s.channels[k].topic: v for k, v in s.statistics.channel_message_counts.items()}
    assert counts == summary["topics"]


def test_demo_trajectory_as_ros2_bag_folder(demo):
    d, traj, _ = demo
    out = d / "pick_place_bag"
    assert run_cli(["export", str(traj), "-o", str(out)]) == 0
    assert (out / "metadata.yaml").is_file() and (out / "pick_place_bag.db3").is_file()
    check_plan_bag(read_bag(out), traj)
    # exporting again replaces the bag (atomically) rather than failing
    assert run_cli(["export", str(traj), "-o", str(out)]) == 0
    assert len(read_bag(out)["/joint_states"]) == len(json.loads(traj.read_text())["points"])


@pytest.mark.parametrize("suffix", [".mcap", "_bag"])
def test_demo_execution_log_commanded_and_measured(demo, suffix):
    d, _, log_path = demo
    out = d / f"pick_place_exec{suffix}"
    assert run_cli(["export", str(log_path), "-o", str(out)]) == 0
    bag = read_bag(out)
    log = json.loads(log_path.read_text())
    # the log carries the trajectory it ran: its samples are the planned joint states and its scene the markers
    assert set(bag) == {"/joint_states/commanded", "/joint_states/measured", "/joint_states/planned", "/scene", "/tf",
                        "/tf_static"}
    assert len(bag["/joint_states/planned"]) >= len(log["trajectory"]["points"])
    sent = [s for s in log["sent"] if s["cmd"].get("T") in (101, 102)]
    fb = [r for r in log["received"] if "feedback" in r]
    cmd, meas = bag["/joint_states/commanded"], bag["/joint_states/measured"]
    assert len(cmd) == len(sent) and len(meas) == len(fb) == len(bag["/tf"])
    # wire -> joints by hand: identity for the five arm joints, hand = pi - gripper (firmware 0.84)
    t102 = [(k, s) for k, s in enumerate(sent) if s["cmd"]["T"] == 102]
    k, s = t102[len(t102) // 2]
    assert np.allclose(cmd[k][2].position[:5], [s["cmd"][f] for f in ("base", "shoulder", "elbow", "wrist", "roll")])
    assert cmd[k][2].position[5] == pytest.approx(math.pi - s["cmd"]["hand"])
    # same spacing in time as the log (shifted so that nothing is negative); a measured state is stamped when the
    # servos were read: the log's read_t where the stream judged the frame, else before its reply crossed the wire
    # (115200 baud 8N1: 11520 B/s) and ~4 ms of firmware work
    read = np.array([x.get("read_t", x["t"] - (len(x["line"]) + 2) / 11520 - 0.004) for x in fb])
    t0 = min(min(x["t"] for x in sent), read.min())
    t_mid, m = meas[len(fb) // 2][0], meas[len(fb) // 2][2]
    same_time = [x["feedback"] for x, t in zip(fb, read) if abs((t - t0) * 1e9 - t_mid) < 1e3]
    assert any(np.allclose(m.position, [r["b"], r["s"], r["e"], r["t"], r["r"], math.pi - r["g"]]) for r in same_time)
    assert np.allclose(np.array([c[0] for c in cmd]) * 1e-9, np.array([x["t"] for x in sent]) - t0, atol=1e-6)
    # a bag is read back in time order; lines that arrived together were read in the order of their lengths
    assert np.allclose(np.array([m[0] for m in meas]) * 1e-9, np.sort(read) - t0, atol=1e-6)


def test_csv_of_trajectory_and_log(demo):
    from roarmctl.motion.validate import load_trajectory

    d, traj_path, log_path = demo
    traj = load_trajectory(traj_path)
    out = d / "pp.csv"
    assert run_cli(["export", str(traj_path), "-o", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == len(traj.times)
    assert np.allclose([float(r["time_s"]) for r in rows], traj.times, atol=1e-6)
    j0 = traj.joint_names[0]
    assert np.allclose([float(r[f"{j0}_rad"]) for r in rows], traj.positions[:, 0], atol=1e-8)
    tcp = np.array([[float(r[f"tcp_{a}_m"]) for a in "xyz"] for r in rows])
    speed = np.array([float(r["tcp_speed_m_s"]) for r in rows])
    # the speed column (J(q) qdot) against the finite difference of the TCP column (different method)
    fd = np.linalg.norm(np.diff(tcp, axis=0), axis=1) / np.diff(traj.times)
    assert np.allclose(0.5 * (speed[1:] + speed[:-1]), fd, atol=0.01)
    assert tcp[0] == pytest.approx(tcp[-1], abs=1e-6)  # the demo starts and ends at home
    out_log = d / "exec.csv"
    assert run_cli(["export", str(log_path), "-o", str(out_log)]) == 0
    rows = list(csv.DictReader(out_log.open()))
    assert {r["source"] for r in rows} == {"commanded", "measured", "planned"}  # planned: the trajectory it carries
    # the same as with -t and the trajectory file
    out_given = d / "exec_given.csv"
    assert run_cli(["export", str(log_path), "-t", str(traj_path), "-o", str(out_given)]) == 0
    assert out_given.read_text() == out_log.read_text()


@pytest.mark.parametrize("name", ["x.txt", "x.png", "x.json"])
def test_unknown_extension_is_exit_2_and_writes_nothing(demo, name, capsys):
    d, traj, _ = demo
    assert run_cli(["export", str(traj), "-o", str(d / name)]) == 2
    assert "unknown export format" in capsys.readouterr().err
    assert not (d / name).exists()


def test_not_a_trajectory_is_exit_2(tmp_path, capsys):
    p = tmp_path / "x.json"
    p.write_text('{"format": "something"}')
    assert run_cli(["export", str(p), "-o", str(tmp_path / "x.mcap")]) == 2
    assert "neither" in capsys.readouterr().err
    assert not (tmp_path / "x.mcap").exists()


def test_damaged_log_is_exit_2(demo, tmp_path, capsys):
    _, _, log_path = demo
    log = json.loads(log_path.read_text())
    log["received"] = [{"feedback": {"T": 1051, "b": 0, "s": 0, "e": 1, "t": 0, "r": 0, "g": 3}}]  # no time
    bad = tmp_path / "bad.exec.json"
    bad.write_text(json.dumps(log))
    assert run_cli(["export", str(bad), "-o", str(tmp_path / "bad.mcap")]) == 2
    assert "received[0].t: expected a number" in capsys.readouterr().err and not (tmp_path / "bad.mcap").exists()


def test_log_with_its_trajectory_adds_planned_states_and_scene(demo, capsys):
    from roarmctl.motion.validate import load_trajectory

    d, traj_path, log_path = demo
    out = d / "run_with_plan.mcap"
    assert run_cli(["export", str(log_path), "-t", str(traj_path), "-o", str(out)]) == 0
    bag = read_bag(out)
    traj = load_trajectory(traj_path)
    log = json.loads(log_path.read_text())
    assert {"/joint_states/planned", "/joint_states/commanded", "/joint_states/measured", "/scene"} <= set(bag)
    planned = bag["/joint_states/planned"]
    # the plan's samples, and where the plan waited for a late host (the log's ``paused``: [plan time the clock
    # stopped at (s, at the run's speed; rounded to 1 us), for how long (s)]; none on a quiet machine) its set-point
    # standing still: a sample at the pause's start (unless one of the plan's is there) and one at its end
    stream_t = np.asarray(traj.times) / log["speed_scale"]
    pauses = [(at, d) for at, d in log.get("paused", []) if 0 <= at <= stream_t[-1] and d > 0]
    before = lambda t: sum(d for at, d in log.get("paused", []) if t > at + 1e-6)  # noqa: E731
    own = stream_t + np.array([before(t) for t in stream_t])
    starts = [at + before(at) for at, _ in pauses if np.abs(stream_t - at).min() > 1e-6]
    ends = [at + before(at) + d for at, d in pauses]
    expected = np.sort(np.concatenate([own, starts, ends]))
    assert len(planned) == len(expected)
    held = np.isin(np.round(expected, 9), np.round(np.concatenate([starts, ends]), 9))
    assert np.allclose([m[2].position for m, h in zip(planned, held) if not h], traj.positions)
    # on the log's clock: the plan's time 0 is when tick 0 was sent (within its lateness)
    sent = [s for s in log["sent"] if s["cmd"].get("T") in (101, 102)]
    k0 = next(k for k, s in enumerate(sent) if s.get("tick") == 0)
    t_tick0 = bag["/joint_states/commanded"][k0][0] * 1e-9
    assert abs(planned[0][0] * 1e-9 - t_tick0) < 0.05
    # spaced as the plan at the run's speed, plus every pause the plan's clock made before a sample
    assert np.allclose(np.diff([m[0] for m in planned]) * 1e-9, np.diff(expected), atol=1e-6)
    assert run_cli(["export", str(traj_path), "-t", str(traj_path), "-o", str(d / "x.mcap")]) == 2
    assert "goes with an execution log" in capsys.readouterr().err
