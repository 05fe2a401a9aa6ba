"""The streaming loop on the virtual clock and link (roarmctl.device.virtual): deterministic schedule, speed scale,
interrupt -> hold, abort on tracking error. No serial port, no real time."""

from __future__ import annotations

import numpy as np
import pytest
from devtraj import HOME, min_jerk

from roarmctl.device.protocol import WireMap, encode
from roarmctl.device.streamer import StreamConfig, Streamer, build_schedule
from roarmctl.device.virtual import VirtualClock, VirtualLink, queued_link
from roarmctl.errors import DeviceError, InfeasibleError, Interrupted
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")


def traj(dur=1.0):
    return min_jerk([HOME, [0.8, 0.3, 1.9, -0.5, 0.3, 0.5]], [dur])


def test_absolute_schedule_without_drift_despite_write_latency():
    clock = VirtualClock()
    link = VirtualLink(clock, write_latency=0.003)
    st = Streamer(link, ROBOT, traj(), StreamConfig(rate=50, settle=0.0), clock=clock, sleep=clock.sleep)
    res = st.run()
    sends = [(t, c) for t, c in link.sent if c["T"] == 102]
    ticks = [(t, c) for t, c in sends if any(c is tk.cmd for tk in st.schedule)]
    times = np.array([t for t, _ in ticks]) - res.t0
    assert len(times) == 51
    assert np.allclose(times, np.arange(51) / 50, atol=1e-9)  # exact k/rate, no accumulated 3 ms
    assert res.lateness.max() < 1e-9


def test_speed_scale_doubles_times_and_halves_speeds():
    fast = build_schedule(traj(), ROBOT, rate=50, speed_scale=1.0)
    slow = build_schedule(traj(), ROBOT, rate=50, speed_scale=0.5)
    assert slow[-1].t == pytest.approx(2 * fast[-1].t)
    assert max(t.cmd["spd"] for t in slow) == pytest.approx(max(t.cmd["spd"] for t in fast) / 2, rel=0.05)
    assert np.allclose(slow[-1].target, fast[-1].target)


def test_interrupt_at_tick_k_holds_on_the_planned_path_never_beyond_the_last_set_point_and_never_torque_off():
    clock = VirtualClock()
    link = VirtualLink(clock)

    def hook(k):
        if k == 20:
            raise KeyboardInterrupt

    t = traj()
    st = Streamer(link, ROBOT, t, StreamConfig(rate=50), clock=clock, sleep=clock.sleep, hook=hook)
    with pytest.raises(Interrupted) as info:
        st.run()
    res = info.value.result
    assert res.outcome == "interrupted" and res.n_sent == 20
    hold = [c for _, c in link.sent if c["T"] == 102][-1]
    assert hold is not st.schedule[19].cmd and hold["spd"] > 0 and hold["acc"] == 0
    assert not [c for _, c in link.sent if c["T"] in (0, 210)]  # never torque off (0.84: T:0 is torque off)
    held = WireMap(ROBOT).from_wire({k: hold[k] for k in ("base", "shoulder", "elbow", "wrist", "roll", "hand")})
    # on the planned path (every joint, the gripper included), at a time no later than the last set-point's
    from roarmctl.device.streamer import sample
    taus = np.linspace(0.0, t.duration, 20001)
    path = sample(t, taus)
    i = int(np.argmin(np.max(np.abs(path - held), axis=1)))
    assert np.max(np.abs(path[i] - held)) < 2e-4
    last_target = st.schedule[19].t + 0.02 + 0.0124 + st.lead  # the last tick targets one interval + latency (+ lead) ahead
    assert taus[i] <= last_target + 1e-3
    assert taus[i] >= st.schedule[19].t - 0.02  # and not behind where the arm was sent
    assert res.log["summary"]["outcome"] == "interrupted" and len(res.log["sent"]) == len(link.sent)
    assert res.log["hold"]["kind"] == "path"


def test_a_hold_lost_to_a_full_receive_buffer_is_sent_again_and_runs():
    """The firmware's loop slows to 200 ms a pass (long feedback lines, failing servo reads) while 800 bytes queue
    up at its UART: the ESP32's receive buffer (256 + 128 bytes) loses the newest bytes, the hold's line among them,
    and the T:105 behind it. The second copy of the hold, sent once the firmware has read what came before, runs.
    (Before: one copy, lost; the arm went on to its last set-point.)"""
    clock = VirtualClock()
    link = VirtualLink(clock)

    def hook(k):
        if k == 20:
            link.fw.cfg.loop_period = 0.2
            link.fw.receive(b'{"junk":"' + b"x" * 390 + b'"}\n' + b'{"junk":"' + b"y" * 390 + b'"}\n', clock())
            raise KeyboardInterrupt

    st = Streamer(link, ROBOT, traj(), StreamConfig(rate=50), clock=clock, sleep=clock.sleep, hook=hook)
    with pytest.raises(Interrupted) as info:
        st.run()
    ticks = {id(tk.cmd) for tk in st.schedule}
    holds = [(t, c) for t, c in link.sent if c["T"] == 102 and id(c) not in ticks]
    assert len(holds) == 2 and holds[0][1] == holds[1][1]  # the same goal twice
    ran = [(t_line, c) for t_line, _, c in link.fw.executed if c == holds[0][1]]
    assert link.fw._rx_dropped >= 2 and len(ran) == 1  # the first copy was lost, the second ran
    assert ran[0][0] > holds[1][0]
    assert info.value.result.log["hold"]["copies"] == 2 and info.value.result.log["hold"]["confirmed"]


def test_stalled_arm_aborts_on_tracking_error():
    clock = VirtualClock()
    link = VirtualLink(clock, stall=True)
    link.fw.info_print = 2  # a deaf device still streams its (unchanging) pose
    st = Streamer(link, ROBOT, traj(0.6), StreamConfig(rate=50, max_error=0.01), clock=clock, sleep=clock.sleep)
    with pytest.raises(DeviceError, match="tracking error"):
        st.run()


def test_start_far_from_first_point_is_refused():
    clock = VirtualClock()
    link = VirtualLink(clock)
    t = min_jerk([[0.5, 0.0, 1.5708, 0, 0, 0], [0.6, 0.0, 1.5708, 0, 0, 0]], [0.5])
    with pytest.raises(InfeasibleError, match=r"base_link_to_link1 is 0\.1 deg, the start is 28\.6 deg"):
        Streamer(link, ROBOT, t, StreamConfig(), clock=clock, sleep=clock.sleep).run()
    assert all(c["T"] == 105 for _, c in link.sent)


def test_trajectory_outside_the_firmware_range_is_refused():
    from roarmctl.errors import InputError

    bad = min_jerk([HOME, [0.0, 0.0, -1.0, 0.0, 0.0, 0.0]], [1.0])  # elbow below the 0.84 clamp (-0.785)
    with pytest.raises(InputError, match=r"link2_to_link3 .* outside the firmware's range for 'elbow'"):
        build_schedule(bad, ROBOT)


@pytest.mark.slow
def test_a_host_stall_makes_the_plan_wait_the_arm_stays_on_it_and_a_stalled_arm_still_aborts():
    """A busy machine stops the streaming process for 150 ms mid-motion, where the TCP moves fastest: the plan
    waits (its clock pauses for the stall, less what was left until the tick was due), every tick goes out in
    order, and the arm, stopped on the path meanwhile, is compared with the plan's own time: no tracking error
    beyond what a run without the stall has. The same stall with an arm that does not follow still aborts."""
    def stalled_at(k_stall: float, stall: float, deaf: bool, max_error: float = 0.03):
        clock = VirtualClock()
        link = VirtualLink(clock, stall=deaf)
        if deaf:
            link.fw.info_print = 2

        def hook(k):
            if k == k_stall:
                clock.now += stall  # the process got no CPU for this long

        st = Streamer(link, ROBOT, traj(1.0), StreamConfig(rate=50, max_error=max_error), clock=clock,
                      sleep=clock.sleep, hook=hook)
        return st, st.run

    st, run = stalled_at(25, 0.15, deaf=False)
    res = run()
    assert res.outcome == "completed" and len(res.lateness) == len(st.schedule)  # every tick, none skipped
    assert [k for k, _ in st.sent_lateness] == list(range(len(st.schedule)))  # in order
    assert len(st.paused) == 1 and st.paused[0][0] == pytest.approx(st.schedule[25].t)
    assert 0.15 - 0.02 <= st.paused[0][1] <= 0.15 and st.waits["late"] == 1
    assert res.lateness.max() < 0.02  # each tick went out within its (paused) schedule
    calm_st, calm = stalled_at(-1, 0.0, deaf=False)
    calm()
    err = np.array([e for _, e in st.tracking])
    calm_err = np.array([e for _, e in calm_st.tracking])
    assert err.max() <= calm_err.max() + 0.002  # on the plan's time, the stall costs no tracking error
    _, run = stalled_at(25, 0.15, deaf=True)
    with pytest.raises(DeviceError, match="tracking error"):
        run()


@pytest.mark.slow  # plans the detour around the post first (62 s at load 20)
def test_a_host_stall_in_a_detour_makes_the_run_late_never_cut_across_the_obstacle():
    """The move to the start around a post (tests/device/test_where_the_arm_is.py), streamed while the host stops
    for 0.4 s after one tick, at every tick of the detour in turn: the plan waits for the host (the next tick goes
    out, not the one due by the clock), so the servos, which run straight from one goal to the next, stay on the
    planned path and never touch the post (FCL at padding 0 on the firmware model's servo positions). Jumping to the
    tick due after such a stall cut the corner into the post (before the fix: stalls of 0.3 s at ticks 6-18, 0.4 s at
    ticks 0-20 of the 61)."""
    import math
    import tempfile
    from pathlib import Path

    from test_where_the_arm_is import POST, plan_text

    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.motion.replan import plan_between
    from roarmctl.motion.scene import Scene
    from roarmctl.robot.ik import solve_ik

    with tempfile.TemporaryDirectory() as d:
        plan = Path(d) / "post.yaml"
        plan.write_text(plan_text(obstacles=POST))
        whole = plan_file(plan).trajectory
    strict = CollisionChecker(ROBOT, Scene.from_dict(whole.scene), padding=0.0)
    arm = ROBOT.arm_indices
    q_away = solve_ik(ROBOT, [0.3 * math.cos(1.2), 0.3 * math.sin(1.2), 0.06], pitch=math.pi / 2)[0]
    detour = plan_between(whole, ROBOT, q_away, whole.positions[0], "move to the start")
    wm = WireMap(ROBOT)
    n_ticks = len(build_schedule(detour, ROBOT, rate=50))
    for j in range(0, n_ticks - 1, 2):
        clock = VirtualClock()
        link = VirtualLink(clock)
        link.fw.receive(encode(wm.command(q_away, 0, 0)), clock())  # the arm stands on the far side of the post
        clock.now += 3.0
        link.fw.advance(clock())
        start = clock()

        def hook(k, j=j, clock=clock):
            if k == j:
                clock.now += 0.4  # the process got no CPU for this long

        st = Streamer(link, ROBOT, detour, StreamConfig(rate=50, settle=0.3), clock=clock, sleep=clock.sleep, hook=hook)
        res = st.run()
        assert res.outcome == "completed" and len(res.lateness) == n_ticks  # every tick sent, in order
        # the plan waited for the host: the stall less what was left until the tick was due (the 50 ms lead at tick 0)
        assert 0.4 - 0.05 - 1e-9 <= sum(d for _, d in st.paused) <= 0.4
        ts, q, _ = link.fw.recording()
        moving = q[ts >= start]
        assert np.abs(moving[-1][arm] - whole.positions[0][arm]).max() < 0.01  # it got there
        assert strict.first_invalid(moving[:, arm]) is None, f"stall after tick {j}"


# ----------------------------------------------------------------------------- a slow 20260701 loop
def pick_like(dur=2.0):
    """An arm move with the gripper closing on the way (its own T:101 lines beside the T:102)."""
    return min_jerk([HOME, [0.8, 0.3, 1.9, -0.5, 0.3, 1.2], [-0.4, 0.2, 1.6, 0.2, -0.3, 0.2]], [dur / 2, dur / 2])


@pytest.mark.parametrize("loop_pass", [0.014, 0.022, 0.030])
def test_a_slow_queued_loop_is_paced_by_its_measured_time_the_rate_lowered_and_its_lag_logged(loop_pass):
    """The 20260701 build with a slow loop: every line waits in its queue at most the time in flight the stream gives
    it (plus the line ahead of it), the motion ends when planned (the stream gave the firmware's time to motion lines,
    fewer polls and no gripper line of its own, and lowered its rate where that was not enough), and the log has the
    firmware's lag. Before: 12 lines in flight by count and an allowance that grew with the lag measured: at 22 ms a
    pass lines waited 230-270 ms and the motion ran 7.6 s long on the bundled pick and place."""
    clock = VirtualClock()
    link = queued_link(clock, loop_pass)
    t = pick_like()
    st = Streamer(link, ROBOT, t, StreamConfig(rate=50, settle=0.0), clock=clock, sleep=clock.sleep)
    res = st.run()
    assert res.outcome == "completed"
    ticks = {id(tk.cmd) for tk in st.schedule}
    waits = np.array([c - t_line for t_line, c, cmd in link.fw.executed if cmd.get("T") in (101, 102)])
    sent = {id(c): tt for tt, c in link.sent}
    assert waits.max() <= 0.05 + 2 * loop_pass + 0.02  # queue wait bounded by time, not a count
    last = max(c for _, c, cmd in link.fw.executed if cmd.get("T") == 102)
    assert last - res.t0 - t.duration <= 0.1  # the motion keeps its planned time
    assert st.firmware_bound and res.log["rate_changes"] == st.rate_changes
    assert (st.rate < 50) == bool(st.rate_changes) and (loop_pass < 0.02 or st.rate < 50)
    assert all(id(tk.cmd) in sent for tk in st.schedule) and len(ticks) == len(st.schedule)  # every tick went out
    lag = res.log["firmware_lag_ms"]
    assert lag["polls"] > 5 and lag["max"] is not None and res.log["firmware_lag"]
    notes = " ".join(res.log["notes"])
    assert "the firmware is the bottleneck" in notes and ("rate lowered" in notes) == bool(st.rate_changes)


LOOP_PASSES = [0.006, 0.014, 0.022, 0.030]  # s: the model's own pass, the figure measured on that build, slower


def off_path(t, recording, since: float) -> float:
    """The recorded TCP's largest distance (m) from the planned TCP path (anywhere on it) from ``since`` on."""
    from roarmctl.device.streamer import sample

    ts, q, _ = recording
    path = ROBOT.kin.fk(ROBOT.full_q(sample(t, np.linspace(0.0, t.duration, 4001))))[:, :3, 3]
    tcp = ROBOT.kin.fk(ROBOT.full_q(q[ts >= since]))[:, :3, 3]
    return max(float(np.min(np.linalg.norm(path - p, axis=1))) for p in tcp)


@pytest.fixture(scope="module")
def fast_loop_off_path():
    """How far off the planned path the arm runs when the 20260701 build's loop keeps up (6 ms a pass, 50 Hz)."""
    clock = VirtualClock()
    link = queued_link(clock, 0.006)
    t = pick_like()
    res = Streamer(link, ROBOT, t, StreamConfig(rate=50, settle=0.0), clock=clock, sleep=clock.sleep).run()
    clock.now += 0.5
    link.fw.advance(clock())
    return off_path(t, link.fw.recording(), res.t0)


@pytest.mark.parametrize("loop_pass", LOOP_PASSES)
def test_a_slow_queued_loop_keeps_the_arm_on_the_path_as_a_fast_one_does(loop_pass, fast_loop_off_path):
    """Each of the firmware's passes goes to motion lines once it is the bottleneck (a poll every 0.2 s, whose 324-byte
    answer holds its loop longer than a motion line; no T:101 of the gripper's own): the stream keeps a rate at which
    the servos' straight runs from goal to goal stay as close to the planned path as at a 6 ms pass, and the motion
    keeps its planned time. Before: polls at 10-12.5/s and the gripper's own lines took most of the loop, the rate fell
    to 10-12 Hz, and the arm ran 9-15 mm off the path (6.8 mm at 6 ms) on 100 ms chords."""
    clock = VirtualClock()
    link = queued_link(clock, loop_pass)
    t = pick_like()
    res = Streamer(link, ROBOT, t, StreamConfig(rate=50, settle=0.0), clock=clock, sleep=clock.sleep).run()
    clock.now += 0.5
    link.fw.advance(clock())
    assert res.outcome == "completed"
    assert off_path(t, link.fw.recording(), res.t0) <= fast_loop_off_path + 5e-4
    last = max(c for _, c, cmd in link.fw.executed if cmd.get("T") == 102)
    assert last - res.t0 - t.duration <= 0.1  # the motion keeps its planned time


def ctrl_c_at(t, loop_pass: float, stop: float):
    """Stream ``t`` to the 20260701 model with ``loop_pass`` s passes and Ctrl-C once ``stop`` of its duration has gone
    by (in the stream's sleep, where it waits most of the time): (streamer, link, clock, when, the log)."""
    clock = VirtualClock()
    link = queued_link(clock, loop_pass)
    stopped: list[float] = []

    def sleep(dt: float) -> None:
        clock.sleep(dt)
        if not stopped and st.sent_lateness and clock() - st.t0 >= stop * t.duration:
            stopped.append(clock())
            raise KeyboardInterrupt

    st = Streamer(link, ROBOT, t, StreamConfig(rate=50), clock=clock, sleep=sleep)
    with pytest.raises(Interrupted) as info:
        st.run()
    return st, link, clock, stopped[0], info.value.result.log


HOLD_STOPS = (0.2, 0.35, 0.5, 0.65, 0.8)  # Ctrl-C at these shares of the motion


def hold_travel(t, link, stopped_at: float) -> float:
    """The farthest (m) the TCP got from where it was at the Ctrl-C (the model's recording, the arm at rest after)."""
    ts, q, _ = link.fw.recording()
    tcp = ROBOT.kin.fk(ROBOT.full_q(q[ts >= stopped_at]))[:, :3, 3]
    return float(np.linalg.norm(tcp - tcp[0], axis=1).max())


@pytest.fixture(scope="module")
def fast_loop_hold_travel():
    """The hold's farthest TCP travel after a Ctrl-C at ``HOLD_STOPS`` when the 20260701 loop keeps up (6 ms a pass)."""
    travels = []
    for stop in HOLD_STOPS:
        _, link, clock, stopped_at, _ = ctrl_c_at(pick_like(), 0.006, stop)
        clock.now += 1.0
        link.fw.advance(clock())
        travels.append(hold_travel(pick_like(), link, stopped_at))
    return max(travels)


@pytest.mark.slow
@pytest.mark.parametrize("loop_pass", LOOP_PASSES)
def test_the_queued_hold_stops_on_the_path_never_ahead_never_back_and_its_answer_is_paired(loop_pass,
                                                                                             fast_loop_off_path,
                                                                                             fast_loop_hold_travel):
    """Ctrl-C on the 20260701 build at times all through the move (wherever the stream is then, mostly waiting for its
    next tick, as a real Ctrl-C comes): the queue is flushed first, then the answers of the polls that ran are read,
    the arm is let finish the last line the firmware ran, and the hold is the point of the plan nearest where it
    stopped: on the planned path, never ahead of the last line the firmware ran, not pulled back (the hold at the last
    confirmed tick, sent before anything was read, brought the arm back up to 8.7 mm along the path at 22 ms:
    bench/bench_slow_loop.py), and from the interrupt on the arm goes no farther and no further off the path than at a
    6 ms pass (before the stream's changes for a slow firmware, the servos fell behind a draining queue and ran 10-100 ms
    chords: up to 22.4 mm at 14 ms and 50.0 mm at 30 ms against 18.3 at 6 ms, 8-15 mm off the path). Its confirmation
    does not wait for the answers to polls the flush discarded: every hold has its ``answered_after_s`` (7 of 10 on the
    20260701 build had none once)."""
    from roarmctl.device.streamer import sample

    t = pick_like()
    wm = WireMap(ROBOT)
    taus = np.linspace(0.0, t.duration, 4001)
    path = sample(t, taus)
    travels = []
    for stop in HOLD_STOPS:
        st, link, clock, stopped_at, log = ctrl_c_at(t, loop_pass, stop)
        hold = log["hold"]
        assert hold["flushed_queue"] and hold["kind"] == "measured_on_path" and "answered_after_s" in hold
        flush = next(tt for tt, c in link.sent if c.get("T") == 0)
        ran = [cmd for _, c, cmd in link.fw.executed if cmd.get("T") == 102]  # the stream's ran before the flush did
        by_cmd = {id(tk.cmd): i for i, tk in enumerate(st.schedule)}
        ran_ticks = [i for _, c in link.sent if (i := by_cmd.get(id(c))) is not None and c in ran]
        held = wm.from_wire(dict(zip(wm.field_names, hold["wire"])))
        gap = np.max(np.abs(path - held), axis=1)
        assert gap.min() < 2e-3  # on the planned path
        last_ran = np.argmin(np.max(np.abs(path - st.schedule[max(ran_ticks)].target), axis=1))
        assert taus[np.argmin(gap)] <= taus[last_ran] + 0.005  # never ahead of what the firmware ran
        clock.now += 1.0
        link.fw.advance(clock())
        ts, q, _ = link.fw.recording()
        tcp = ROBOT.kin.fk(ROBOT.full_q(q[ts >= flush]))[:, :3, 3]
        far = np.linalg.norm(tcp - tcp[0], axis=1)
        assert far.max() - far[-1] < 1e-3  # not pulled back along the path
        assert off_path(t, link.fw.recording(), stopped_at) <= fast_loop_off_path + 5e-4
        travels.append(hold_travel(t, link, stopped_at))
    assert max(travels) <= fast_loop_hold_travel + 5e-4  # the hold moves the TCP no more than at a 6 ms pass


@pytest.mark.parametrize("where", ["in_send", "after_send"])
def test_a_stop_signal_at_any_point_of_a_send_leaves_the_log_counting_what_went_out(monkeypatch, where):
    """A real SIGTERM arrives while tick 20's line is going out (inside the link's send) or just after (while the
    pacing records it), with the CLI's signal handling: the log's count of motion commands, its message and its
    tick-tagged 'sent' entries all equal the ticks whose line went out (a clean-clone CI run logged 41 ticks sent
    and counted 40: the signal had come between the send and its record)."""
    import os
    import signal

    from roarmctl.cli import signals
    from roarmctl.device import pacing

    clock = VirtualClock()
    ticks_out = []

    class SignalledLink(VirtualLink):
        def send(self, cmd, fresh_line=False):
            t = super().send(cmd, fresh_line)
            if cmd.get("T") == 102 and len(self.sent) and where == "in_send":
                ticks_out.append(cmd)
                if len(ticks_out) == 20:
                    os.kill(os.getpid(), signal.SIGTERM)  # the handler runs at the next bytecode: still in send
            return t

    link = SignalledLink(clock)
    if where == "after_send":
        real = pacing.Pacer.sent

        def sent(self, n_lines, arrive, tick=None):
            real(self, n_lines, arrive, tick)
            if tick == 19:
                os.kill(os.getpid(), signal.SIGTERM)

        monkeypatch.setattr(pacing.Pacer, "sent", sent)
    st = Streamer(link, ROBOT, traj(), StreamConfig(rate=50), clock=clock, sleep=clock.sleep, shield=signals.shielded)
    with signals.installed(), pytest.raises(Interrupted) as info:
        st.run()
    log = info.value.result.log
    scheduled = {id(tk.cmd) for tk in st.schedule}
    on_wire = sum(1 for _, c in link.sent if id(c) in scheduled)
    tagged = sum(1 for e in log["sent"] if "tick" in e)
    assert log["summary"]["outcome"] == "terminated"
    assert on_wire == 20 and tagged == 20 and log["summary"]["commands"] == 20
    assert "after 20 of " in log["summary"]["message"]
