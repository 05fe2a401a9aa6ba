"""The corpus of published arms (issue 22, item 4): each arm's published description files as they are
(tests/data/arms/NAME/, see SOURCE and assemble.py) with a sidecar of at most ten lines, through the CLI:
the files are the published bytes (git blob ids), ``kin fk`` agrees with an independent chain product,
``kin ik`` solutions put the TCP on the target by FK, ``plan`` picks a block and carries it over a wall
within every limit, and ``export`` writes an MCAP whose joint states carry the mimic joints as their
leaders move them.

The arms are planned once per module (``planned``), the work shared by the tests that read the result."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from roarmctl.cli import run as run_cli

CORPUS = Path(__file__).parent / "data" / "arms"
ARMS = sorted(p.name for p in CORPUS.iterdir() if (p / "robot.yaml").is_file())
GRIPPERLESS = {"ur5e", "irb2400", "gen3", "gp7", "rx160"}  # published without a gripper: their plans move the TCP along the same path
# Published descriptions roarmctl does not load yet: known defects, strict xfails (an arm that starts to load turns
# its xfail into a failure: remove it here then). None at the moment.
PENDING: dict[str, str] = {}
# make test-fast loads the issue's three arms; make test every arm (each load ~0.5-1 s of CPU)
INNER = {"xarm6", "wx250s", "gen3_lite"}
LOADING_FAST = [pytest.param(a, marks=[*([pytest.mark.xfail(reason=PENDING[a], strict=True)] if a in PENDING else []),
                                       *([] if a in INNER else [pytest.mark.slow])]) for a in ARMS]


def source_entries(arm: str) -> dict[str, str]:
    """SOURCE's files and meshes: path -> blob id ('hull of <id>' for a mesh stored as its hull)."""
    out, section = {}, None
    for line in (CORPUS / arm / "SOURCE").read_text().splitlines():
        if re.match(r"^(files|meshes):", line):
            section = line.split(":")[0]
        elif section and line.startswith("  "):
            path, _, value = line.strip().rpartition(": ")
            out[path] = value
    return out


def git_blob(data: bytes) -> str:
    """Git's id of a file's bytes (the id ``git rev-parse COMMIT:PATH`` prints for the published file)."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def test_the_corpus_has_at_least_fifteen_arms_and_those_of_the_issues():
    assert len(set(ARMS) - set(PENDING)) >= 15
    # issue 22's three; issue 33's: dict(...) with keywords (gen3), a YAML key given twice (fr3), effort="-1"
    # and <passive_joint> inside a <group> (ar4)
    assert {"xarm6", "wx250s", "gen3_lite", "gen3", "fr3", "ar4"} <= set(ARMS) - set(PENDING)


@pytest.mark.parametrize("arm", ARMS)
def test_files_are_the_published_ones_and_the_sidecar_is_short(arm):
    entries = source_entries(arm)
    described = [p for p, v in entries.items() if not v.startswith("hull of")]
    assert len(described) >= 2  # the description and its licence at least
    for path in described:
        assert git_blob((CORPUS / arm / path).read_bytes()) == entries[path], path
    side = (CORPUS / arm / "robot.yaml").read_text().splitlines()
    lines = [s for s in side if s.strip() and not s.lstrip().startswith("#")]
    assert len(lines) <= 10, lines
    src = (CORPUS / arm / "SOURCE").read_text()
    assert re.search(r"^repository: https://github.com/\S+$", src, re.M) and re.search(r"^commit: [0-9a-f]{40}$", src, re.M)
    assert re.search(r"^licence: \S", src, re.M)
    # every file the sidecar names is among the published files (nothing edited beside them)
    data = yaml.safe_load("\n".join(side))
    for key in ("urdf", "srdf", "joint_limits"):
        if key in data:
            assert data[key] in entries, key


@pytest.mark.slow
@pytest.mark.parametrize("arm", LOADING_FAST)
def test_kin_fk_matches_an_independent_chain_product(arm, capsys):
    """``kin fk --json`` at a configuration inside the limits equals the naive chain product of the loaded
    joints (origin @ motion(multiplier q + offset) @ post, written out in test_kinematics)."""
    from test_kinematics import naive_link_frames

    from roarmctl.robot.loader import load_robot

    robot = load_robot(str(CORPUS / arm / "robot.yaml"))
    q = robot.lower + (robot.upper - robot.lower) * np.linspace(0.3, 0.7, robot.dof)
    capsys.readouterr()
    assert run_cli(["kin", "fk", str(CORPUS / arm / "robot.yaml"), *[f"{v:.12g}" for v in q], "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    ref = naive_link_frames(robot, np.array([float(f"{v:.12g}") for v in q]))[robot.kin.tcp_index]
    np.testing.assert_allclose(out["position"], ref[:3, 3], atol=1e-9)
    np.testing.assert_allclose(out["rotation"], ref[:3, :3], atol=1e-9)
    assert out["q_units"] == ["m" if p else "rad" for p in robot.prismatic]


def _first_target(plan: dict) -> list[float]:
    if plan.get("objects"):
        return list(plan["objects"][0]["xyz"])
    return list(plan["tasks"][0]["move"]["xyz"])


@pytest.mark.slow
@pytest.mark.parametrize("arm", LOADING_FAST)
def test_kin_ik_solutions_reach_the_target_by_fk(arm, capsys):
    """``kin ik`` to the plan's first target with the tool pointing straight down: each solution is within
    the limits and its TCP, by the library's FK, is on the target with its approach axis (TCP +x) down."""
    from roarmctl.robot.loader import load_robot

    robot = load_robot(str(CORPUS / arm / "robot.yaml"))
    plan = yaml.safe_load((CORPUS / arm / "plan.yaml").read_text())
    target = _first_target(plan)
    target[2] += 0.05  # the approach point above it
    capsys.readouterr()
    assert run_cli(["kin", "ik", str(CORPUS / arm / "robot.yaml"), "--xyz", *map(str, target), "--pitch", "90", "--deg",
                    "--all", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solutions"]
    for sol in out["solutions"]:
        q = robot.from_user(np.array(sol), True)
        assert robot.within_limits(q)
        t = robot.kin.fk(q)
        np.testing.assert_allclose(t[:3, 3], target, atol=1e-6)
        assert t[:3, 0] @ [0, 0, -1] > np.cos(1e-4)


class _Planned(dict):
    """Each arm's plan planned with ``roarmctl plan`` the first time a test asks for it: arm -> (exit code,
    trajectory file). Only the arms this worker's tests read are planned (all of them took ~15 s of CPU per worker)."""

    def __init__(self, folder: Path) -> None:
        super().__init__()
        self.folder = folder

    def __missing__(self, arm: str) -> tuple[int, Path]:
        traj = self.folder / f"{arm}.traj.json"
        self[arm] = (run_cli(["plan", str(CORPUS / arm / "plan.yaml"), "-o", str(traj), "--json"]), traj)
        return self[arm]


@pytest.fixture(scope="module")
def planned(tmp_path_factory) -> dict[str, tuple[int, Path]]:
    """Every arm's plan, planned once per worker when first read (``_Planned``)."""
    return _Planned(tmp_path_factory.mktemp("corpus"))


def planned_file(planned: dict, arm: str) -> Path:
    """The trajectory of ``arm``'s plan; its ``roarmctl plan`` exited 0."""
    code, traj = planned[arm]
    assert code == 0, arm
    return traj


# The two tests that read an arm's trajectory run on one xdist worker (--dist loadgroup): each arm is planned once.
PLANNED = [pytest.param(a, marks=[pytest.mark.xdist_group(f"corpus-{a}"),
                                  *([pytest.mark.xfail(reason=PENDING[a], strict=True)] if a in PENDING else [])])
           for a in ARMS]


@pytest.mark.slow
@pytest.mark.parametrize("arm", PLANNED)
def test_plan_picks_over_the_wall_within_every_limit(arm, planned):
    """The trajectory, checked against the robot by the validator execute uses and by hand: every sample
    within the joint limits, the velocities within the scaled limits, the grasp and the release where the
    plan puts the block (by FK), and the TCP higher than the wall where it crosses the wall's plane."""
    from roarmctl.motion.validate import validate_trajectory
    from roarmctl.robot.loader import load_robot

    traj = validate_trajectory(planned_file(planned, arm))
    robot = load_robot(str(CORPUS / arm / "robot.yaml"))
    q = traj.positions
    assert np.all(q >= robot.lower - 1e-9) and np.all(q <= robot.upper + 1e-9)
    vmax = robot.velocity_limits * traj.limits["velocity_scale"]
    assert np.all(np.abs(traj.velocities) <= vmax * 1.02 + 1e-9)
    plan = yaml.safe_load((CORPUS / arm / "plan.yaml").read_text())
    tcp = robot.kin.fk(q)[:, :3, 3]
    if arm not in GRIPPERLESS:
        kinds = [e.kind for e in traj.events]
        assert kinds == ["grasp", "release"]
        at = lambda t: int(np.argmin(np.abs(traj.times - t)))  # noqa: E731
        np.testing.assert_allclose(tcp[at(traj.events[0].time)], plan["objects"][0]["xyz"], atol=1e-4)
        np.testing.assert_allclose(tcp[at(traj.events[1].time)], plan["tasks"][1]["place"]["xyz"], atol=1e-4)
    wall = plan["scene"]["obstacles"][0]
    yaw = wall["rpy"][2]
    normal = np.array([-np.sin(yaw), np.cos(yaw), 0.0])  # the wall is thin across this direction
    along = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    side = (tcp - wall["xyz"]) @ normal
    crossing = np.flatnonzero(np.sign(side[:-1]) != np.sign(side[1:]))
    assert len(crossing) >= 1  # from the pick side to the place side
    # where the TCP crosses the wall's plane within its length, it is higher than the wall (else it went around)
    over = crossing[np.abs((tcp[crossing] - wall["xyz"]) @ along) <= wall["size"][0] / 2]
    assert np.all(tcp[over, 2] > wall["size"][2])


@pytest.mark.slow
@pytest.mark.parametrize("arm", PLANNED)
def test_export_writes_an_mcap_with_every_joint(arm, planned, tmp_path):
    """``export`` writes the MCAP; read back with rosbags, its joint states name every movable joint of the
    URDF, the mimic joints at multiplier x leader + offset (the URDF's own <mimic> numbers, read here)."""
    from test_export import read_bag

    from roarmctl.robot.loader import load_robot

    out = tmp_path / f"{arm}.mcap"
    traj_file = planned_file(planned, arm)
    assert run_cli(["export", str(traj_file), "-o", str(out)]) == 0
    msgs = read_bag(out)
    robot = load_robot(str(CORPUS / arm / "robot.yaml"))
    first = msgs["/joint_states"][len(msgs["/joint_states"]) // 2][2]
    names = list(first.name)
    assert names[:robot.dof] == robot.joint_names
    mimics = [j for j in robot.joints if j.mimic is not None]
    for j in mimics:
        lead = first.position[names.index(j.mimic)]
        assert first.position[names.index(j.name)] == pytest.approx(j.multiplier * lead + j.offset, abs=1e-12)
    assert set(robot.held_joints) <= set(names)
    assert len(msgs["/joint_states"]) == len(json.loads(traj_file.read_text())["points"])


@pytest.mark.slow
@pytest.mark.parametrize("arm", PLANNED)
def test_visualize_path_draws_the_planned_arm(arm, planned, tmp_path):
    """``visualize-path`` draws the trajectory to a PNG (the robot rebuilt from the trajectory's own description)."""
    out = tmp_path / f"{arm}.png"
    assert run_cli(["visualize-path", str(planned_file(planned, arm)), "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
