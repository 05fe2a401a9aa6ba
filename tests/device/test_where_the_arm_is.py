"""Where the arm is, run after run, on the firmware simulator: start: current after the arm was moved by T:102
commands (over a real pty: plan --port reads it), and on one simulated arm on a virtual clock that every
``execute --sim`` connects to (``clirun.virtual_simulator(arm)``: the arm stays where the last run or the hand left
it, as on sim-device, with no real time) a trajectory run twice in a row, the gripper opened/closed first,
--move-to-start around an obstacle and --from-current. The simulator's recorded servo positions are the independent
check (collisions with python-fcl through the checker at padding 0, TCP by FK)."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from clirun import virtual_simulator

from roarmctl.cli import main
from roarmctl.device.protocol import WireMap, encode
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.device.virtual import VirtualClock, VirtualSimulator
from roarmctl.motion.validate import load_trajectory
from roarmctl.robot.ik import solve_ik
from roarmctl.robot.loader import load_robot

pytestmark = pytest.mark.slow  # plans and runs whole trajectories (one of them in real time on a pty)

# execute --sim on the one virtual arm: ideal servos, as behind sim-device's pty; goals compensated for sag, as
# execute --port sends them
SIM = ["--sim", "--servos", "ideal", "--sag"]

R = load_robot("roarm_m3_pro")
ARM = R.arm_indices
GI = R.joint_index(R.gripper.joint)
ROOT = Path(__file__).resolve().parents[2]
COUNT = 2 * math.pi / 4096


def run_cli(args: list[str]) -> int:
    try:
        main(args)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


def hand_move(sim: PtySimulator, q: np.ndarray, timeout: float = 15.0) -> None:
    """Move the simulated arm like a user would with a T:102 from a serial terminal; return once the
    simulator's servos stand still at ``q`` (within 3 counts)."""
    import serial

    with serial.Serial(sim.path, 115200, timeout=0.1) as s:
        s.write(encode(WireMap(R).command(q, 800, 0)))
        s.flush()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        time.sleep(0.1)
        ts, qs, _ = sim.recording()
        if np.abs(qs[-1] - q).max() < 3 * COUNT and np.ptp(qs[ts > ts[-1] - 0.1], axis=0).max() < 1e-9:
            return
    raise AssertionError(f"the arm did not reach {q} within {timeout} s")


def measured(sim: PtySimulator | VirtualSimulator) -> np.ndarray:
    _, q, _ = sim.recording()
    return q[-1]


def virtual_arm() -> VirtualSimulator:
    """The simulated arm (the 0.84 build, ideal servos) on a virtual clock, powered up."""
    return VirtualSimulator(SimConfig(), VirtualClock()).start()


def virtual_hand_move(sim: VirtualSimulator, q: np.ndarray) -> None:
    """``hand_move`` on the virtual arm: the T:102 into its UART, then its clock on until its servos stand still at
    ``q`` (within 3 counts)."""
    assert sim.firmware is not None
    sim.firmware.receive(encode(WireMap(R).command(q, 800, 0)), sim.clock())
    for _ in range(300):  # 30 s of its clock: a hang detector
        sim.clock.sleep(0.1)
        sim.firmware.advance(sim.clock())
        ts, qs, _ = sim.recording()
        if np.abs(qs[-1] - q).max() < 3 * COUNT and np.ptp(qs[ts > ts[-1] - 0.1], axis=0).max() < 1e-9:
            return
    raise AssertionError(f"the arm did not reach {q} within 30 s of its clock")


POST = "    - {name: post, shape: box, size: [0.12, 0.04, 0.22], xyz: [0.2146, 0.1468, 0.11], rpy: [0, 0, 0.6]}\n"


# the robot's full joint speed and acceleration (the plans' default is half): what is checked here is where
# the arm is between runs, not how fast it gets there, and each test streams its runs in real time
FAST = "velocity_scale: 1.0, acceleration_scale: 1.0"


def plan_text(start: str = "home", obstacles: str = "", end: str = "  - move: {pose: home, gripper: closed}\n",
              limits: str = FAST) -> str:
    return ("robot: roarm_m3_pro\nstart: " + start + "\nscene:\n  table: {shape: box, size: [0.80, 0.60, 0.02], "
            "xyz: [0.15, 0.0, -0.01]}\n" + ("  obstacles:\n" + obstacles if obstacles else "") +
            "objects:\n  - {name: cube, shape: box, size: [0.04, 0.04, 0.04], xyz: [0.25, -0.15, 0.02], mass: 0.03}\n"
            "tasks:\n  - pick: {object: cube}\n  - place: {xyz: [0.25, -0.05, 0.02]}\n" + end +
            "limits: {" + limits + "}\nplanner: {seed: 2}\n")


def about_the_start(notes: list[str]) -> list[str]:
    """A run's notes but the stream's own pacing ("rate lowered ...", "the firmware is the bottleneck ...": on a busy
    machine the firmware's answers come late and the stream slows down for them, as it should), which say nothing
    about where the arm started."""
    return [n for n in notes if not n.startswith(("rate lowered", "the firmware is the bottleneck"))]


def test_start_current_after_the_arm_was_moved_by_hand(tmp_path, capsys):
    """In real time on the simulator's pty: plan --port reads where the hand left the arm, execute --port runs it."""
    plan = tmp_path / "here.yaml"
    plan.write_text(plan_text(start="current"))
    q_hand = R.full_q(np.array([-0.6, 0.3, 1.3, 0.4, 0.2]))
    q_hand[GI] = 0.7
    with PtySimulator(SimConfig(), process=True) as sim:
        hand_move(sim, q_hand)
        out = tmp_path / "here.traj.json"
        rc = run_cli(["plan", str(plan), "--port", sim.path, "-o", str(out), "--json"])
        summary = json.loads(capsys.readouterr().out)
        assert rc == 0
        assert any("start: current" in n for n in summary["notes"])
        traj = load_trajectory(out)
        assert traj.positions[0] == pytest.approx(q_hand, abs=2 * COUNT)  # joints and gripper, as measured
        assert traj.positions[0] == pytest.approx(measured(sim), abs=1e-6)
        rc = run_cli(["execute", str(out), "--port", sim.path, "--yes", "--json"])  # no flag needed: it is there
        assert rc == 0, capsys.readouterr().err
        assert about_the_start(json.loads(capsys.readouterr().out)["notes"]) == []


def test_a_port_given_to_a_plan_that_does_not_start_at_current_is_named_unused(tmp_path, capsys):
    """``plan --sim`` (or ``--port``) with a plan that starts at a named pose: the arm is not read, and the command
    says so in its warnings (it planned from the plan's own start, which the trajectory shows)."""
    out = tmp_path / "p.traj.json"
    assert run_cli(["plan", str(ROOT / "plans" / "pick_place.yaml"), "--sim", "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [w for w in summary["warnings"] if w.startswith("--sim was not used")], summary["warnings"]
    assert not [n for n in summary["notes"] if "measured pose" in n]


def test_the_demo_trajectory_runs_twice_in_a_row(tmp_path, capsys):
    out = tmp_path / "pp.traj.json"
    assert run_cli(["plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    traj = load_trajectory(out)
    sim = virtual_arm()
    with virtual_simulator(sim):
        for run in range(2):
            rc = run_cli(["execute", str(out), *SIM, "--yes", "--json"])
            res = json.loads(capsys.readouterr().out)
            assert rc == 0 and res["outcome"] == "completed", (run, res)
            # it ended where it started: nothing to re-plan (at most the gripper, whose servo may still be
            # creeping to its last goal at the final command's low speed, is closed the last bit first)
            assert all("gripper differs" in n for n in about_the_start(res["notes"])), res["notes"]
            at = measured(sim)
            assert at[ARM] == pytest.approx(traj.positions[-1][ARM], abs=0.01)
            assert abs(at[GI] - traj.positions[-1][GI]) < 0.35  # the streamer's gripper start tolerance
        grips = [c for _, _, c in sim.executed() if c.get("T") == 101 and c.get("joint") == 6]
        assert grips  # the gripper really moved in the runs


def test_only_the_gripper_differs_it_is_opened_or_closed_first(tmp_path, capsys):
    plan = tmp_path / "open_end.yaml"
    plan.write_text(plan_text(end="  - move: {pose: home}\n"))  # ends with the gripper open
    out = tmp_path / "open_end.traj.json"
    assert run_cli(["plan", str(plan), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    traj = load_trajectory(out)
    assert abs(traj.positions[-1][GI] - traj.positions[0][GI]) > 1.0
    sim = virtual_arm()
    with virtual_simulator(sim):
        virtual_hand_move(sim, traj.positions[-1])  # where a run of it left the arm: its end, the gripper open
        rc = run_cli(["execute", str(out), *SIM, "--yes", "--json"])
        res = json.loads(capsys.readouterr().out)
        assert rc == 0 and res["outcome"] == "completed"
        assert any("gripper" in n and "planned and checked" in n for n in res["notes"])
        log = json.loads((tmp_path / "open_end.exec.json").read_text())
        assert log["final_pose"]["world_m"] == pytest.approx(R.kin.fk(traj.positions[-1])[:3, 3], abs=0.005)
        fb = next(e for e in log["received"] if "tcp_world_m" in e)
        assert fb["feedback"]["z"] == pytest.approx((fb["tcp_world_m"][2] - 0.122059) * 1000, abs=3.5)  # both frames


def test_move_to_start_goes_around_an_obstacle(tmp_path, capsys):
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene

    plan = tmp_path / "post.yaml"
    plan.write_text(plan_text(obstacles=POST))
    out = tmp_path / "post.traj.json"
    assert run_cli(["plan", str(plan), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    traj = load_trajectory(out)
    strict = CollisionChecker(R, Scene.from_dict(traj.scene), padding=0.0)
    # the arm stands low on the far side of the post: the straight joint move to the start hits it
    q_away = solve_ik(R, [0.3 * math.cos(1.2), 0.3 * math.sin(1.2), 0.06], pitch=math.pi / 2)[0]
    straight = np.linspace(q_away, traj.positions[0], 200)
    assert strict.first_invalid(straight[:, ARM]) is not None
    sim = virtual_arm()
    with virtual_simulator(sim):
        virtual_hand_move(sim, q_away)
        t_start = sim.clock()
        rc = run_cli(["execute", str(out), *SIM, "--yes"])
        assert rc == 3 and "--move-to-start" in capsys.readouterr().err
        rc = run_cli(["execute", str(out), *SIM, "--yes", "--move-to-start", "--json"])
        res = json.loads(capsys.readouterr().out)
        assert rc == 0 and res["outcome"] == "completed"
        assert any("collision-checked motion" in n for n in res["notes"])
        ts, q, _ = sim.recording()
    moving = q[ts > t_start]
    arrived = int(np.argmax(np.max(np.abs(moving[:, ARM] - traj.positions[0][ARM]), axis=1) < 0.01))
    assert arrived > 100  # it did travel from the far side to the start
    # what the servos really did on the way to the start never touched the post (or the table)
    assert strict.first_invalid(moving[:arrived:2, :][:, ARM]) is None
    assert not any(c.get("spd") == 300 and c.get("acc") == 10 for _, _, c in sim.executed())  # no bare T:102


def test_from_current_replans_the_first_free_motion(tmp_path, capsys):
    out = tmp_path / "pp.traj.json"
    assert run_cli(["plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    traj = load_trajectory(out)
    q_away = R.full_q(np.array([0.4, 0.1, 1.4, 0.2, 0.0]))
    sim = virtual_arm()
    with virtual_simulator(sim):
        virtual_hand_move(sim, q_away)
        rc = run_cli(["execute", str(out), *SIM, "--yes", "--from-current", "--json"])
        res = json.loads(capsys.readouterr().out)
        assert rc == 0 and res["outcome"] == "completed", res
        assert any("again from the measured pose" in n for n in res["notes"])  # the plan file is there: planned again
        assert measured(sim)[ARM] == pytest.approx(traj.positions[-1][ARM], abs=0.01)
        log = json.loads((tmp_path / "pp.exec.json").read_text())
        # never went back to the trajectory's own start (home) before the pick
        assert log["duration"] < traj.duration + 1.0
        # the log carries the trajectory that ran (planned from where the arm stood), not the file's
        from roarmctl.device.execlog import carried_trajectory

        ran = carried_trajectory(log)
        assert ran is not None and ran.positions[0][ARM] == pytest.approx(q_away[ARM], abs=0.02)
        assert np.abs(ran.positions[0][ARM] - traj.positions[0][ARM]).max() > 0.1


def test_from_current_without_the_plan_file_replaces_the_first_free_motion(tmp_path, capsys):
    plan = tmp_path / "stops.yaml"
    plan.write_text(plan_text(limits=FAST + ", blend: false"))
    out = tmp_path / "stops.traj.json"
    assert run_cli(["plan", str(plan), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    plan.unlink()  # the plan is gone: only the trajectory is left to splice
    traj = load_trajectory(out)
    free = next(s for s in traj.segments if s.kind == "free")
    q_away = R.full_q(np.array([-0.5, 0.1, 1.4, 0.2, 0.0]))
    sim = virtual_arm()
    with virtual_simulator(sim):
        virtual_hand_move(sim, q_away)
        rc = run_cli(["execute", str(out), *SIM, "--yes", "--from-current", "--json"])
        res = json.loads(capsys.readouterr().out)
        assert rc == 0 and res["outcome"] == "completed", res
        assert any("re-planned the first free motion" in n for n in res["notes"])
        log = json.loads((tmp_path / "stops.exec.json").read_text())
        # the rest of the trajectory, after the first free motion, was streamed as planned
        first = float(next(n for n in res["notes"] if "re-planned" in n).split(": ")[1].split(" s")[0])
        assert log["duration"] == pytest.approx(first + traj.duration - free.end, abs=0.02)
        assert measured(sim)[ARM] == pytest.approx(traj.positions[-1][ARM], abs=0.01)
