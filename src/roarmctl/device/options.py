"""How a trajectory is streamed to the arm (``StreamConfig``): the device layer's options object, which ``execute``
(the CLI and ``roarmctl.api.execute``) builds and ``roarmctl.device.streamer.Streamer`` takes. It checks its own
fields when it is made (``roarmctl.checks.check_options``, bounds in ``STREAM_BOUNDS``): NaN, infinities,
wrong types and values out of range raise ``OptionError`` naming the field. A NaN tracking bound (``max_error``)
would switch the tracking stop off (no comparison with NaN is true), so none gets this far.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from roarmctl.checks import Bound, check_options
from roarmctl.device.schedule import DEFAULT_RATE, DEFAULT_STRATEGY, MAX_LINK_RATE, STRATEGIES, Strategy
from roarmctl.formats import MIN_SPEED_SCALE

HOLD_MODES = ("auto", "path", "setpoint", "measured")

STREAM_BOUNDS: dict[str, Bound] = {
    "rate": Bound(0.0, MAX_LINK_RATE, strict_lo=True),  # T:102 lines/s: 115200 baud carries about 90
    "speed_scale": Bound(MIN_SPEED_SCALE, 1.0),  # fraction of the planned speed
    "strategy": Bound(choices=tuple(STRATEGIES)),
    "max_error": Bound(0.0, 1.0, strict_lo=True),  # m: a metre of tracking error is no bound on any arm described here
    "start_tolerance": Bound(0.0, math.pi),  # rad per arm joint
    "gripper_tolerance": Bound(0.0, 2 * math.pi),  # rad
    "move_to_start": Bound(flag=True),
    "from_current": Bound(flag=True),
    "stale_after": Bound(0.0, 60.0, strict_lo=True),  # s
    "settle": Bound(0.0, 60.0),  # s
    "lead": Bound(0.0, 10.0),  # s
    "hold": Bound(choices=HOLD_MODES),
    "hold_max_age": Bound(0.0, 10.0),  # s
    "feedback_rate": Bound(0.0, 1000.0, strict_lo=True, optional=True),  # polls/s
    "in_flight": Bound(0.0, 10.0),  # s
    "behind_after": Bound(0.0, 10.0),  # s
    "sag": Bound(flag=True),
}


@dataclass(frozen=True)
class StreamConfig:
    """Streaming options. Times in s, distances in m, angles in rad; bounds in ``STREAM_BOUNDS``. ``strategy``: a
    name of ``roarmctl.device.schedule.STRATEGIES`` (or a ``Strategy`` itself, for the benchmarks)."""

    rate: float = DEFAULT_RATE
    speed_scale: float = 1.0
    strategy: str = DEFAULT_STRATEGY
    max_error: float = 0.03  # TCP position error before aborting
    start_tolerance: float = 0.05  # per arm joint between the measured pose and the first point
    gripper_tolerance: float = 0.35  # the gripper's own
    move_to_start: bool = False  # arm elsewhere: a planned motion to the start first (needs ``replan``)
    from_current: bool = False  # arm elsewhere: the first free motion planned again from here (needs ``replan``)
    stale_after: float = 0.3  # a T:105 unanswered this long during motion (plus measured lateness) -> stop
    settle: float = 0.6  # to wait for the arm to arrive after the last command
    lead: float = 0.05  # between the start decision and the first command
    hold: str = "auto"  # "auto", "path", "setpoint" or "measured" (see roarmctl.device.streamer)
    hold_max_age: float = 0.05  # a measured pose older than this is never held
    feedback_rate: float | None = None  # T:105 polls/s; None: FEEDBACK_RATE, half that on a build that queues
    in_flight: float = 0.05  # s of the firmware's time (measured per line) the unconfirmed lines may represent
    behind_after: float = 0.04  # a poll answered this much later than the round trip: the firmware is behind
    sag: bool = False  # goals offset by the servos' sag (roarmctl.device.sag); execute and the API default on: sag.wanted

    def __post_init__(self) -> None:
        own = isinstance(self.strategy, Strategy)  # a strategy object itself (the benchmarks): no name to check
        bounds = {k: b for k, b in STREAM_BOUNDS.items() if not (own and k == "strategy")}
        check_options(self, bounds)
