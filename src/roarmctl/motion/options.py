"""The motion layer's options: how fast a plan may move (``Limits``) and how its paths are searched
(``PlannerConfig``). A plan file's ``limits`` and ``planner`` become these (``roarmctl.plan.schema`` reads each
field against the bound written here, naming the file and line), and so do the arguments of
``roarmctl.api.Planner``. Each object checks its own fields when it is made (``roarmctl.checks.check_options``):
NaN, infinities, wrong types and values out of range raise ``OptionError`` naming the field; none exists out of
bounds, and none changes after (frozen: ``dataclasses.replace`` makes a changed copy, checked again).
"""

from __future__ import annotations

from dataclasses import dataclass

from roarmctl.checks import MAX_WHOLE, Bound, check_options

PLANNERS = ("RRTConnect", "RRTstar", "BITstar", "PRM", "KPIECE1")

LIMITS_BOUNDS: dict[str, Bound] = {
    # fractions of the robot's joint velocity and acceleration limits: above 1 the description's limits would be
    # broken; below 1 % nothing is gained (the README's pick and place takes 6.8 s at 0.6, 105 s at 0.02, so about
    # half an hour at 0.001, near the 3600 s a trajectory may last).
    "velocity_scale": Bound(0.01, 1.0),
    "acceleration_scale": Bound(0.01, 1.0),
    # m/s the TCP may move: 5 m/s is beyond what the arms described here reach (a UR's tool tops out near 3 m/s),
    # 1 mm/s is slower than anything useful; outside, likely a unit mistake. None: no cap.
    "max_tcp_speed": Bound(0.001, 5.0, optional=True),
    "gripper_time": Bound(0.05, 10.0),  # s an open or close takes
    "blend": Bound(flag=True),
    # m a move's path may pass its target at and flow on (0: reached): 1 m is beyond any corner of the arms described
    # here; a zone larger than the way to the next target is refused when planning.
    "zone": Bound(0.0, 1.0),
}

PLANNER_BOUNDS: dict[str, Bound] = {
    "name": Bound(choices=PLANNERS),
    "time_budget": Bound(0.0, 600.0, strict_lo=True),  # s
    "simplify_budget": Bound(0.0, 60.0),  # s
    "max_checks": Bound(1_000, 1_000_000_000, whole=True),
    "seed": Bound(0, MAX_WHOLE, whole=True),
    # m/rad, the smallest singular value of the translational Jacobian a state keeps: it scales with the arm's reach
    # (sampled maxima: roarm_m3_pro 0.23, ur5e 0.33, ur10 0.45), so the cap is for any arm, only a typo's catch; a
    # margin beyond what the arm can keep refuses its start.
    "singularity_margin": Bound(0.0, 1.0),
    # m the arm is inflated against the scene: a clearance for the model's and the arm's errors, which grow with its
    # size, so the cap is for any arm (a UR10 reaches 1.3 m: 5 cm is not much there); beyond 0.1 m it is more likely
    # millimetres written as metres, and a padding the scene cannot leave room for refuses the start or the targets.
    "padding": Bound(0.0, 0.1),
}


@dataclass(frozen=True)
class Limits:
    """How fast a plan moves: scales of the robot's joint velocity and acceleration limits (fractions), the TCP
    speed cap (m/s, None: none), the gripper's action time (s), blending (False: stop at every join) and the
    default zone of a move target (m). Bounds: ``LIMITS_BOUNDS``."""

    velocity_scale: float = 0.5
    acceleration_scale: float = 0.5
    max_tcp_speed: float | None = None
    gripper_time: float = 0.6
    blend: bool = True  # flow through pre-grasp points and open the gripper in transit; False: stop at every join
    zone: float = 0.0  # m: a move target's zone unless it gives its own (0: reached, the TCP within ZONE_REACHED)

    def __post_init__(self) -> None:
        check_options(self, LIMITS_BOUNDS)


@dataclass(frozen=True)
class PlannerConfig:
    """How paths are searched: the OMPL planner's name, work and time budgets, seed, singularity margin (m/rad)
    and padding (m). Bounds: ``PLANNER_BOUNDS``."""

    name: str = "RRTConnect"
    time_budget: float = 10.0  # s, wall-clock safety ceiling per planner call (never changes the result)
    simplify_budget: float = 5.0  # s, wall-clock safety ceiling per shortcutting call
    max_checks: int = 2_000_000  # work budget: state checks per planner call (this decides "no path")
    seed: int = 0
    singularity_margin: float = 0.02
    padding: float = 0.005

    def __post_init__(self) -> None:
        check_options(self, PLANNER_BOUNDS)
