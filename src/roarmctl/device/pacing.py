"""How fast a stream may feed the firmware: the lines in flight bounded by the firmware's measured time per line,
its lag (the time a line waited behind others), and the tick rate it can keep up with.

The firmware answers ``T:105`` polls in order, so an answer confirms every line sent before its poll. Waveshare's
20260701 build queues the lines its serial task reads (``serialCtrl`` in ``uart_ctrl.h``: a FreeRTOS queue of 50
lines) and ``loop()`` runs one of them per pass, so a stream faster than the loop builds a backlog that a later
hold waits behind; the 0.84 build runs every waiting line in one pass (``uart_ctrl.h`` lines 384-407 of the
``RoArm-M3_example-250108`` copy in github.com/jhacksman/RoArm-M3). From the confirmations the pacer learns

- the firmware's **lag**: how much later than the round trip measured at connect a poll was answered (a lower
  bound: the last read of the link before the answer was there), the time it waited behind other lines;
- its **time per line**: between two answers where every line between them had been sent before the first answer
  came (the firmware ran them back to back), the time between the answers over the lines they confirm, averaged
  (it starts at what ``connect()`` measured);

and bounds the stream by time, not by a count: the unconfirmed lines times the time per line may not exceed
``in_flight`` seconds, however slow the firmware is. A stream whose lines per second times the time per line
exceed ``FIRMWARE_SHARE`` of the firmware is too fast for it: ``fitting_rate`` names the tick rate that fits
(never below ``MIN_RATE``), and the streamer goes on at that rate, so the motion keeps its planned time instead
of running late behind a queue. The pacer never raises the rate again (a firmware that was slow once may be
slow again). No allowance here grows with the lateness measured: a firmware that falls further behind is given
less, not more.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

#: Share of the firmware's line capacity (1 / time per line) a stream may plan to use: the rest absorbs the
#: passes a poll answer makes longer (a 324-byte T:1051 holds the 20260701 loop while the UART drains) and jitter.
FIRMWARE_SHARE = 0.8
MIN_RATE = 10.0  # Hz: the least tick rate the pacer lowers a stream to
LOWER_BY = 0.9  # a new rate is named only when it is at most this share of the current one (no churn)
EWMA = 0.3  # weight of a new time-per-line sample


@dataclass
class Pacer:
    """The stream's book of lines and polls, and its model of the firmware's queue. Times in s on the streamer's
    clock; ``rtt``: the unloaded T:105 round trip measured at connect; ``line_time``: the firmware's time per command
    line measured at connect (about 0 on the 0.84 build, a loop pass on the 20260701 build), then from the answers;
    ``in_flight``: the firmware time the lines it has not run yet may represent (what a new line waits at most)."""

    rtt: float
    line_time: float
    in_flight: float
    lines: int = 0  # lines sent (commands and polls)
    confirmed: int = 0  # lines confirmed by a poll answer
    polls: deque[tuple[float, int, float]] = field(default_factory=deque)  # (on the wire from, lines up to it, wait)
    lag: list[tuple[float, float]] = field(default_factory=list)  # (answer read at, lag s) of every poll answered
    samples: int = 0  # time-per-line samples taken
    confirmed_tick: int | None = None  # the last tick every line of which a poll answer confirmed
    done_at: float = -math.inf  # when the firmware had run every confirmed line (answer read, less its wire time)
    _ticks: deque[tuple[int, int]] = field(default_factory=deque)  # (lines up to and with the tick, tick)
    _batches: deque[tuple[float, int, int]] = field(default_factory=deque)  # unconfirmed: (at the firmware, lines, up to)

    def sent(self, n_lines: int, arrive: float, tick: int | None = None) -> None:
        """``n_lines`` command lines went out, the last of them at the firmware at ``arrive`` (the lines of ``tick``)."""
        self.lines += n_lines
        self._batches.append((arrive, n_lines, self.lines))
        if tick is not None:
            self._ticks.append((self.lines, tick))

    def poll_sent(self, on_wire: float, arrive: float, now: float) -> None:
        """A ``T:105`` went out at ``now``; its round trip starts ``on_wire`` (when the bytes ahead of it have left),
        it reaches the firmware at ``arrive``."""
        wait = self.backlog(now)
        self.sent(1, arrive)
        self.polls.append((on_wire, self.lines, wait))

    def free_at(self) -> float:
        """When the firmware will have run every line sent (the model: the confirmed ones done at ``done_at``, each
        other line ``line_time`` after it arrived or the one before it was done)."""
        f = self.done_at
        for arrive, n, _ in self._batches:
            f = max(f, arrive) + n * self.line_time
        return f

    def backlog(self, now: float) -> float:
        """The firmware time (s) the lines sent and not run yet represent at ``now``: what a new line waits."""
        return max(0.0, self.free_at() - now) if self._batches else 0.0

    def answered(self, read_at: float, read_before: float, reply_wire: float) -> float:
        """The oldest poll's answer (``reply_wire`` s on the wire) was read at ``read_at`` (and was not there at
        ``read_before``); return when that poll went out. Updates what is confirmed, the lag and the time per line."""
        t_poll, upto, _ = self.polls.popleft()
        self.lag.append((read_at, max(0.0, read_before - t_poll - self.rtt)))
        done = read_at - reply_wire
        ran = [b for b in self._batches if b[2] <= upto]
        if ran and self.confirmed > 0 and ran[-1][0] <= self.done_at:
            # every line up to this poll was at the firmware when it had run the previous one: it ran them back to back
            sample = (done - self.done_at) / (upto - self.confirmed)
            self.line_time = (1 - EWMA) * self.line_time + EWMA * max(0.0, sample)
            self.samples += 1
        while self._batches and self._batches[0][2] <= upto:
            self._batches.popleft()
        self.done_at = max(self.done_at, done)
        self.confirmed = max(self.confirmed, upto)
        while self._ticks and self._ticks[0][0] <= self.confirmed:
            self.confirmed_tick = self._ticks.popleft()[1]
        return t_poll

    def overdue(self, now: float, allowance: float) -> bool:
        """Whether the oldest poll waits for its answer longer than the round trip, the wait the model gave it when it
        went out and a fixed ``allowance``: the firmware is slower than measured."""
        if not self.polls:
            return False
        t_poll, _, wait = self.polls[0]
        return now - t_poll > self.rtt + wait + allowance

    def unconfirmed(self) -> int:
        """Lines sent and not yet confirmed."""
        return self.lines - self.confirmed

    def may_send(self, now: float, n_lines: int) -> bool:
        """Whether ``n_lines`` more lines would run within ``in_flight`` s of the firmware's time (one tick's lines
        always go when the firmware has nothing queued)."""
        wait = self.backlog(now)
        return wait <= 0.0 or wait + n_lines * self.line_time <= self.in_flight

    def fitting_rate(self, rate: float, lines_per_tick: float, lower_by: float = LOWER_BY) -> float | None:
        """A lower tick rate (Hz) when ``rate`` ticks/s of ``lines_per_tick`` lines each need more than
        ``FIRMWARE_SHARE`` of the firmware's time; None when ``rate`` fits (or the new one is not at most ``lower_by``
        of it)."""
        if self.line_time <= 0 or rate * lines_per_tick * self.line_time <= FIRMWARE_SHARE:
            return None
        fit = max(MIN_RATE, FIRMWARE_SHARE / (lines_per_tick * self.line_time))
        return fit if fit <= lower_by * rate else None

    def lag_summary(self) -> dict[str, float | int | None]:
        """The lag of the answered polls for the log's summary: p50, p99, max (ms) and the count."""
        lags = np.array([x for _, x in self.lag]) * 1e3
        if not len(lags):
            return {"p50": None, "p99": None, "max": None, "polls": 0}
        return {"p50": round(float(np.percentile(lags, 50)), 3), "p99": round(float(np.percentile(lags, 99)), 3),
                "max": round(float(lags.max()), 3), "polls": int(len(lags))}
