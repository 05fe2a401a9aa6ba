"""The motion layer's options: how fast a plan may move (``Limits``) and how its paths are searched
(``PlannerConfig``). A plan file's ``limits`` and ``planner`` become these (``roarmctl.plan.schema``), and so do
the arguments of ``roarmctl.api.Planner``."""

from __future__ import annotations

from dataclasses import dataclass

PLANNERS = ("RRTConnect", "RRTstar", "BITstar", "PRM", "KPIECE1")


@dataclass
class Limits:
    """The plan's ``limits``: scales of the robot's joint limits, TCP speed (m/s), gripper time (s), blending."""

    velocity_scale: float = 0.5
    acceleration_scale: float = 0.5
    max_tcp_speed: float | None = None
    gripper_time: float = 0.6
    blend: bool = True  # flow through pre-grasp points and open the gripper in transit; False: stop at every join
    zone: float = 0.0  # m: a move target's zone unless it gives its own (0: reached, the TCP within ZONE_REACHED)


@dataclass
class PlannerConfig:
    """The plan's ``planner``: OMPL planner name, work and time budgets, seed, singularity margin (m/rad), padding (m)."""

    name: str = "RRTConnect"
    time_budget: float = 10.0  # s, wall-clock safety ceiling per planner call (never changes the result)
    simplify_budget: float = 5.0  # s, wall-clock safety ceiling per shortcutting call
    max_checks: int = 2_000_000  # work budget: state checks per planner call (this decides "no path")
    seed: int = 0
    singularity_margin: float = 0.02
    padding: float = 0.005
