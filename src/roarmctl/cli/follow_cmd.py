"""``roarmctl follow``: a leader arm or a policy's JSON lines drive the arm, every target through the guard
(``roarmctl.device.follow_guard``), followed with jerk-limited motion; refusals are said on stderr, a run of them or
a lost source holds the arm and exits 4."""

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from roarmctl.cli import common, signals
from roarmctl.errors import InputError, Interrupted
from roarmctl.fileio import check_writable
from roarmctl.motion.options import PlannerConfig

if TYPE_CHECKING:
    from rich.console import Console

    from roarmctl.device.follow import FollowResult, Source
    from roarmctl.robot.model import Robot


def register(app: typer.Typer) -> None:
    """Add ``follow`` to the app."""
    app.command("follow")(follow)


def follow(
    port: str | None = typer.Option(None, "--port", "-p", help="Serial port of the follower arm (/dev/ttyUSB0, COM3, a pyserial URL)."),
    sim: bool = typer.Option(False, "--sim", help="Follow with the built-in firmware simulator."),
    leader: str | None = typer.Option(None, "--leader", metavar="PORT", help="A leader arm on this port: its torque goes "
                                      "off, a hand moves it, the follower follows its feedback."),
    leader_guide: Path | None = typer.Option(None, "--leader-guide", metavar="FILE", help="A simulated leader arm moved "
                                             "by this hand script (as 'teach --sim --guide' reads it)."),
    socket_path: Path | None = typer.Option(None, "--socket", metavar="PATH", help="Read JSON lines from the process "
                                            "that connects to this new Unix socket (default: stdin)."),
    dataset: Path | None = typer.Option(None, "--dataset", metavar="DIR", help="Replay an episode's action column of "
                                        "this LeRobot v3.0 dataset (with --episode)."),
    episode: int = typer.Option(0, "--episode", help="The episode of --dataset to replay."),
    record: Path | None = typer.Option(None, "--record", metavar="DIR", help="Append the followed episode (the source's "
                                       "targets as action, the arm's measured joints as state) to this LeRobot dataset."),
    record_fps: int = typer.Option(30, "--record-fps", help="Frames per second of the recorded episode."),
    task: str = typer.Option("follow", "--task", help="The recorded episode's task (its instruction text)."),
    scene: Path | None = typer.Option(None, "--scene", metavar="PLAN", help="A plan whose scene, padding, singularity "
                                      "margin and robot the targets are checked against."),
    rate: float = typer.Option(50.0, "--rate", help="Set-points per second sent to the arm."),
    timeout: float = typer.Option(0.5, "--timeout", help="s without a frame before the source counts as lost."),
    max_refusals: int = typer.Option(5, "--max-refusals", help="Refused targets in a row before following ends (exit 4)."),
    frozen_after: float = typer.Option(2.0, "--frozen-after", help="s of bit-identical frames that make a source frozen "
                                       "(0: never)."),
    velocity_scale: float = typer.Option(1.0, "--velocity-scale", help="Share (0-1] of the joint velocity limits a step "
                                         "and the motion may use."),
    acceleration_scale: float = typer.Option(1.0, "--acceleration-scale", help="Share (0-1] of the joint acceleration limits."),
    first_frame: float = typer.Option(30.0, "--first-frame", help="s to wait for the source's first frame."),
    duration: float | None = typer.Option(None, "--duration", help="Stop after this many seconds (default: until the "
                                          "source ends)."),
    log: Path | None = typer.Option(None, "--log", help="Write the follow log (JSON: every target and its verdict, "
                                    "every set-point, the measured poses)."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before the arm moves."),
) -> None:
    """Follow a live source with the arm: a leader arm (--leader PORT) or joint targets as JSON lines
    ({"t": s, "joints": [rad, ...], "gripper": rad}) on stdin or a Unix socket, the form a policy process writes.

    Every target is checked before it moves anything: a fresh frame (not stale, late or frozen), finite, within the
    joint limits, within a per-joint velocity/acceleration step budget, clear of the scene and the arm itself and
    outside the singularity margin at the target and along the way. A refused target is not sent: the arm goes on to
    the last accepted one. After --max-refusals in a row, or no frame for --timeout s, the arm holds and the command
    exits 4. The end of the source's stream ends following (exit 0) at its last accepted target.
    """
    from roarmctl.device.follow import FollowConfig
    from roarmctl.device.follow_guard import GuardLimits
    from roarmctl.device.follow_session import LeaderSpec, follow_live
    from roarmctl.device.follow_sources import SocketSource, StreamSource
    from roarmctl.device.protocol import WireMap
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.pipeline import load_plan_and_robot
    from roarmctl.motion.planning.context import scene_item
    from roarmctl.motion.scene import Scene
    from roarmctl.robot.loader import load_robot

    if (port is None) == (not sim):
        raise InputError("give exactly one of --port PORT and --sim", "e.g. roarmctl follow --sim < targets.jsonl")
    if leader is not None and leader_guide is not None:
        raise InputError("give one leader: --leader PORT or --leader-guide FILE (a simulated one)")
    is_leader = leader is not None or leader_guide is not None
    if sum((is_leader, socket_path is not None, dataset is not None)) > 1:
        raise InputError("give one source: a leader arm, --socket or --dataset")
    # options of another option, given without it, were ignored: a follow of stdin ran with exit 0
    if dataset is None and episode != 0:
        raise InputError("--episode goes with --dataset", "give --dataset DIR, or leave --episode out")
    if record is None and (record_fps != 30 or task != "follow"):
        raise InputError("--record-fps and --task go with --record", "give --record DIR, or leave them out")
    source_plan, robot = (load_plan_and_robot(scene, load=common.load_robot) if scene is not None
                          else (None, load_robot("roarm_m3_pro")))
    WireMap(robot)  # a robot without a RoArm wire map cannot be driven: say so before opening anything
    planner = source_plan.planner if source_plan is not None else PlannerConfig()
    items = [scene_item(s) for s in source_plan.scene + source_plan.objects] if source_plan is not None else []
    checker = CollisionChecker(robot, Scene(items), padding=planner.padding,
                               singularity_margin=planner.singularity_margin or None)
    cfg = FollowConfig(rate=rate, first_frame=first_frame, duration=duration,
                       guard=GuardLimits(velocity_scale=velocity_scale, acceleration_scale=acceleration_scale,
                                         timeout=timeout, frozen_after=frozen_after, max_refusals=max_refusals))
    if log is not None:
        check_writable(log)
    if record is not None:
        _check_record(record, robot, record_fps)
    if port is not None and not yes:
        if not is_leader and socket_path is None and dataset is None:
            raise InputError("refusing to ask for confirmation: the targets come on stdin", "pass --yes to follow without asking")
        if not sys.stdin.isatty():
            raise InputError("refusing to ask for confirmation: stdin is not a terminal", "pass --yes to follow without asking")
        if not typer.confirm(f"The arm on {port} will follow the source. Continue?", default=False, err=True):
            raise Interrupted("not confirmed; the arm did not move")

    err = common.console(stderr=True)
    spec = None
    source: Source | None = None
    if leader_guide is not None:
        from roarmctl.device.guide import load_guide

        spec = LeaderSpec(guide=load_guide(leader_guide))
    elif leader is not None:
        spec = LeaderSpec(port=leader)
    elif dataset is not None:
        source = _replay(dataset, episode, robot)
    elif socket_path is not None:
        source = SocketSource(robot, socket_path)
        err.print(f"waiting for a process to connect to {socket_path}", highlight=False)
    else:
        source = StreamSource(robot, sys.stdin.fileno())

    def event(text: str) -> None:
        style = "yellow" if text.startswith("refused") else ""
        # the text quotes the source's lines ('[rad, ...]', a key it sent): rich markup only around it
        err.print(f"[{style}]{common.shown(text)}[/]" if style else common.one_line(text), highlight=False,
                  markup=bool(style), soft_wrap=True)

    try:
        done = follow_live(robot, checker, port=port, sim=sim, source=source, leader=spec, config=cfg, on_event=event,
                           log_path=log, shield=signals.shielded, on_tick=signals.check)
    except Exception as exc:
        res = getattr(exc, "result", None)
        if res is not None:
            _summary(err, res, log)
            if record is not None:
                _record(err, record, robot, res, record_fps, task)
        raise
    _summary(err, done.result, log)
    if record is not None:
        _record(err, record, robot, done.result, record_fps, task)


def _replay(dataset: Path, episode: int, robot: "Robot") -> "Source":
    """The ``action`` column of one episode of a LeRobot dataset, for this robot."""
    from roarmctl.device.follow_sources import ReplaySource
    from roarmctl.export.lerobot.dataset import read_actions, spec_of

    have = spec_of(dataset)
    if list(have.joint_names) != list(robot.joint_names):
        raise InputError(f"--dataset {dataset}: its joints are {', '.join(have.joint_names)}, the robot's "
                         f"{', '.join(robot.joint_names)}", "replay a dataset of this robot (or give its plan with --scene)")
    t, action = read_actions(dataset, episode)
    return ReplaySource(t, action, f"{dataset} episode {episode}")


def _check_record(root: Path, robot: "Robot", fps: int) -> None:
    """Refuse a --record folder that is not a dataset of this robot and rate before anything moves."""
    from roarmctl.export.lerobot.dataset import INFO_PATH, spec_of

    if not 1 <= fps <= 1000:
        raise InputError(f"--record-fps must be a whole number in [1, 1000], got {fps}")
    if root.exists() and not (root / INFO_PATH).exists() and (not root.is_dir() or any(root.iterdir())):
        raise InputError(f"--record {root}: exists and is not a LeRobot dataset", "give a new folder or a dataset")
    if (root / INFO_PATH).exists():
        have = spec_of(root)
        if (have.fps, list(have.joint_names), have.cameras) != (fps, list(robot.joint_names), {}):
            raise InputError(f"--record {root}: the dataset has fps {have.fps}, joints {', '.join(have.joint_names)} and "
                             f"cameras {', '.join(have.cameras) or 'none'}; a followed episode has fps {fps}, the robot's "
                             "joints and no camera", "record into a new folder or match --record-fps")


def _record(err: "Console", root: Path, robot: "Robot", res: "FollowResult", fps: int, task: str) -> None:
    from roarmctl.export.lerobot.follow_record import record_follow

    try:
        path = record_follow(root, robot, res.log, fps, task)
        err.print(f"recorded the episode into {path}", highlight=False, markup=False)
    except InputError as exc:
        common.warn(f"not recorded: {exc.message}")


def _summary(err: "Console", res: "FollowResult", log: Path | None) -> None:
    s = res.summary()
    t = s.get("targets") or {}
    cost = s.get("cost_ms") or {}
    line = (f"{res.outcome}: {s.get('setpoints', 0)} set-points; targets {t.get('accepted', 0)} accepted, "
            f"{t.get('refused', 0)} refused")
    if cost.get("p50") is not None:
        line += f"; check + motion per target {cost['p50']:.2f} ms median, {cost['max']:.2f} ms max"
    err.print(line, highlight=False, markup=False)
    if log is not None:
        err.print(f"follow log: {log}", highlight=False, markup=False)
