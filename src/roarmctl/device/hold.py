"""The hold: stop the arm at a given goal, with torque on, so that the firmware surely runs it.

One implementation for every loop that moves the arm (``roarmctl.device.streamer`` after a plan's stream,
``roarmctl.device.follow`` after a live source), which choose the goal; this module only gets it run.

On the 20260701 build the firmware's command queue is flushed first with the bytes ``"T":0`` (which on that
build only flushes and sets StopFlag; on the 0.84 build ``T:0`` cuts torque for 10 s and is never sent), then
``"T":999`` clears the flag. The hold goes out twice, the second copy once the firmware has read what came before:
a full receive buffer (256 + 128 bytes on the ESP32) loses the newest bytes, which can be the hold.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device import protocol
from roarmctl.device.protocol import WireMap

if TYPE_CHECKING:
    from roarmctl.device.link import LinkLike, Received

HOLD_SPD = 600  # the firmware's own ARM_SERVO_INIT_SPEED, steps/s: the least speed of a hold


def flush_queue(link: LinkLike, outstanding: int, clock: Callable[[], float], sleep: Callable[[float], None],
                timeout: float = 0.3) -> list[Received]:
    """On the build that queues lines (20260701): flush its queue, then ask where the arm is. Returns the feedback
    read after the flush, in order: the answers to those of the ``outstanding`` polls sent before that ran before the
    flush, then (last, when it came within ``timeout`` s) the answer to the new poll, a pose measured after every line
    that will ever run had run. The caller chooses the hold's goal from them and sends it with ``send_hold(...,
    flushed=True)``: the lines not run yet never run, so the wait for the answer costs no travel.

    That build's serial task flushes its command queue on the bytes "T":0 (and never queues the line); T:999
    clears the StopFlag it sets. Torque stays on. Raises DeviceError when the link is gone."""
    link.send({"T": 0}, fresh_line=True)
    link.send({"T": 999})
    return answers_after_flush(link, outstanding, clock, sleep, timeout)


def send_hold(link: LinkLike, wm: WireMap, wire: np.ndarray, spd: int, *, kind: str, cause: str, earlier: int = 0,
              on_answer: Callable[[Received], object] | None = None, clock: Callable[[], float] | None = None,
              sleep: Callable[[float], None] | None = None, flushed: bool = False) -> dict[str, Any]:
    """Send the hold to firmware radians ``wire`` (fields order) at ``spd`` steps/s (at least ``HOLD_SPD``);
    return what the log keeps of it (``kind``, ``cause``, when, the goal, copies, whether it was confirmed).

    ``earlier``: answers still due to ``T:105`` polls sent before (the firmware answers in order);
    ``on_answer`` hears the feedback that answers after each copy (the caller judges it). ``clock``/``sleep``: the
    caller's (default the link's), for the wait after a flush. ``flushed``: the caller flushed the queue already
    (``flush_queue``) and read its answers; otherwise a build that queues lines has it flushed here first.
    Raises DeviceError when the link is gone.
    """
    queued = link.firmware == "m3-2026"
    flush_here = queued and not flushed
    if flush_here:
        link.send({"T": 0}, fresh_line=True)
        link.send({"T": 999})
    cmd = wm.hold(dict(zip(wm.field_names, (float(v) for v in wire))), max(HOLD_SPD, int(spd)), 0)
    t_hold = link.send(cmd, fresh_line=not flush_here)
    info: dict[str, Any] = {"kind": kind, "cause": cause, "flushed_queue": queued, "t": t_hold,
                            "wire": [protocol.r4(v) for v in wire], "copies": 1}
    # answered after the firmware read the hold's line: bounds the hold's latency
    if flush_here:
        got = answers_after_flush(link, earlier, clock or link.clock, sleep or link.sleep)
        r = got[-1] if got else None
    else:
        r = link.request(0.3, earlier=0 if flushed else earlier)
    if r is not None:
        info["answered_after_s"] = round(r.t - t_hold, 4)
        if on_answer is not None:
            on_answer(r)
    # a second copy, sent when the firmware has read all that came before (or nothing answered in 0.3 s), finds
    # the receive buffer empty; the hold is a fixed goal, so running it twice changes nothing
    link.send(cmd, fresh_line=True)
    info["copies"] = 2
    r2 = link.request(0.3)
    info["confirmed"] = r2 is not None
    if r2 is not None and on_answer is not None:
        on_answer(r2)
    return info


def answers_after_flush(link: LinkLike, outstanding: int, clock: Callable[[], float], sleep: Callable[[float], None],
                        timeout: float = 0.3) -> list[Received]:
    """Send a T:105 after a flushed queue and return the feedback read, its answer last (none if nothing came within
    ``timeout`` s).

    The ``outstanding`` polls sent before were either run before the flush (their answers come first) or flushed with
    the queue (no answer ever comes): waiting for all of them, as without a flush, waited out the timeout and
    confirmed nothing (7 of 10 holds on the 20260701 build had no ``answered_after_s``). The firmware answers in order
    and prints nothing unasked (InfoPrint 0), so the last answer read within ``timeout`` is this one's; once
    ``outstanding + 1`` are read there is nothing left to wait for.
    """
    link.send(protocol.feedback_request())
    end = clock() + timeout
    frames: list[Received] = []
    while len(frames) <= outstanding and clock() < end:
        frames += [r for r in link.poll() if r.feedback is not None]
        if len(frames) <= outstanding:
            sleep(0.005)
    return frames
