"""execute --sim on the physics servos (MuJoCo, the ST3235 model): the arm follows its goals about
46 ms late (the P-only position loop, ``roarmctl.device.st3235.LOOP_LAG``). The tracking check must
take that lag for what it is, and still stop an arm that does not move."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from roarmctl.cli import run as run_cli
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.physics.servo_backend import for_firmware
from roarmctl.robot.loader import load_robot

pytestmark = pytest.mark.slow  # real time, physics behind the simulated firmware

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def planned(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("phys") / "pick_place.traj.json"
    assert run_cli(["plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(out), "--json"]) == 0
    return out


def test_a_lagging_arm_is_not_a_fault(planned, capsys, virtual_sim):
    """Streamed without a lead, the physics arm's TCP is 20 mm behind the plan at speed (bench_stream:
    timed, 0.84 build): more than a 15 mm bound, yet the run completes, because the arm is on the path,
    late by the servos' own lag."""
    capsys.readouterr()
    rc = run_cli(["execute", str(planned), "--sim", "--servos", "physics", "--strategy", "timed", "--yes", "--json",
                  "--max-error", "15", "--log", str(planned.with_name("lag.exec.json"))])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["outcome"] == "completed", res
    sim = res["simulator"]
    assert sim["max_mm"] > 15.0, sim  # the raw error does exceed the bound: the lag is real here
    assert sim["torque_always_on"]


def test_a_blocked_joint_on_the_physics_arm_still_aborts_with_a_hold(planned, capsys):
    traj_robot = load_robot("roarm_m3_pro")
    log = planned.with_name("stuck.exec.json")
    with PtySimulator(SimConfig(stuck=("shoulder",)), servos=for_firmware(traj_robot), process=True) as sim:
        rc = run_cli(["execute", str(planned), "--port", sim.path, "--yes", "--max-error", "20", "--log", str(log)])
        _, _, torque = sim.recording()
    err = capsys.readouterr().err
    assert rc == 4 and "tracking error" in err and "exceeds 20 mm" in err, err
    data = json.loads(log.read_text())
    assert data["summary"]["outcome"] == "aborted" and data["hold"] is not None and torque.all()



def test_the_default_strategy_follows_the_plan_on_the_physics_arm(planned, capsys, virtual_sim):
    """The default strategy aims ahead by the loop's lag: the arm is on the plan, not behind it."""
    capsys.readouterr()
    rc = run_cli(["execute", str(planned), "--sim", "--yes", "--json", "--log", str(planned.with_name("lead.exec.json"))])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["outcome"] == "completed", res
    # bench_stream: 2.8 mm RMS with the lead (10.0 mm without, its lag 44 ms); aligned within the lateness
    # measured on the busy machine
    assert res["simulator"]["rms_aligned_mm"] < 6.0, res["simulator"]
    # what the streamer measured from the feedback (each frame dated when its servos were read) agrees
    # with the simulator's truth: a poll sent behind a command's bytes is dated from when it left the UART
    print(f"\nfeedback: RMS {res['tracking_mm']['rms']:.2f} mm over {res['tracking_mm']['samples']}; "
          f"truth: RMS {res['simulator']['rms_mm']:.2f} mm")
    assert abs(res["tracking_mm"]["rms"] - res["simulator"]["rms_mm"]) < 2.0, (res["tracking_mm"], res["simulator"])
