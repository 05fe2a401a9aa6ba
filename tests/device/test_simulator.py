"""The firmware model alone, with explicit times (deterministic, no threads)."""

import math

import pytest

from roarmctl.device.protocol import encode, parse_feedback
from roarmctl.device.simulator import Firmware, SimConfig, firmware_fk, firmware_ik

BYTE = 1 / 11520


def fw(**kw) -> Firmware:
    return Firmware(SimConfig(info_print=0, **kw), t0=0.0)


def feedback(f: Firmware, t: float):
    f.receive(b'{"T":105}\n', t)
    f.advance(t + 0.1)
    lines = [parse_feedback(x) for x in f.pop_output(t + 0.1).split(b"\r\n") if x]
    return [x for x in lines if x][-1]


def test_boot_pose_reads_one_count_off_and_fk_matches_firmware_constants():
    f = fw()
    fb = feedback(f, 0.0)
    c = 2 * math.pi / 4096
    assert fb.joints["base"] == pytest.approx(c, abs=1e-6)  # middle is 2047, not 2048
    assert fb.joints["shoulder"] == pytest.approx(-c, abs=1e-6)
    assert fb.joints["elbow"] == pytest.approx(math.pi / 2, abs=1e-6)
    assert fb.joints["hand"] == pytest.approx(math.pi, abs=1e-6)
    assert firmware_fk(0, 0, math.pi / 2, 0)[:3] == pytest.approx((346.16, 0, 223.13), abs=0.01)
    for q in [(0.3, 0.4, 1.0, 0.5), (-1.0, 0.2, 2.0, -0.7)]:
        assert firmware_ik(*firmware_fk(*q)) == pytest.approx(q, abs=1e-9)


def test_reply_timing_follows_the_byte_rate():
    f = fw()
    f.receive(b'{"T":105}\n', 1.0)
    f.advance(1.05)
    (t_done, line), = f.out
    t_in = 1.0 + 10 * BYTE
    # run by the first loop pass after the line is in (a pass reads six servos), the T:105 reads the
    # six servos again, then len(line) bytes on the wire
    one_pass = 6 * f.cfg.read_time + f.overhead
    assert t_in + 6 * f.cfg.read_time <= t_done - len(line) * BYTE <= t_in + 2 * one_pass + 1e-9
    assert line.endswith(b"}\r\n")


def test_trapezoid_with_speed_and_acceleration():
    f = fw()
    f.receive(encode({"T": 102, "base": 0.5, "shoulder": 0, "elbow": 1.5708, "wrist": 0, "roll": 0, "hand": math.pi,
                      "spd": 500, "acc": 10}), 0.0)
    d = 2047 - round(0.5 / (2 * math.pi) * 4096) - 2047  # -326 steps (base is inverted)
    v, a = 500.0, 1000.0
    expected = abs(d) / v + v / a  # cruise + ramps (time of a trapezoid)
    t_start = 120 * BYTE
    f.advance(t_start + expected - 0.05)
    assert f.servos.pos[0] != 2047 + d
    f.advance(t_start + expected + 0.03)
    assert f.servos.pos[0] == 2047 + d


def test_malformed_lines_dropped_and_missing_keys_read_as_zero():
    f = fw()
    f.receive(b'{"T":102,"base":1.0,\n', 0.0)  # broken: dropped silently
    f.receive(b'garbage\n', 0.0)
    f.receive(encode({"T": 102, "base": 0.2, "shoulder": 0.1, "elbow": 1.2, "hand": 3.0, "spd": 0, "acc": 0}), 0.0)
    f.advance(1.0)
    assert f.out == type(f.out)()  # no reply to anything
    fb = feedback(f, 1.0)
    assert fb.joints["base"] == pytest.approx(0.2, abs=2 * 2 * math.pi / 4096)
    assert fb.joints["wrist"] == pytest.approx(0.0, abs=2 * 2 * math.pi / 4096)  # missing wrist drove it to 0
    assert len(f.received) == 2


def test_emergency_stop_drops_torque_and_blocks_for_10s_scaled():
    f = fw(time_factor=0.1)
    f.receive(b'{"T":0}\n', 0.0)
    f.receive(b'{"T":105}\n', 0.01)
    f.advance(0.5)
    assert not f.servos.torque().any() and f.pop_output(0.5) == b""  # blocked
    f.advance(1.2)
    assert f.servos.torque().all() and b'"T":1051' in f.pop_output(1.2)
    _, _, torque = f.recording()
    assert not torque.all()


def test_info_print_2_streams_feedback_bandwidth_bound():
    f = Firmware(SimConfig(info_print=2), t0=0.0)
    f.advance(1.0)
    n = len(f.pop_output(1.0).split(b"\r\n")) - 1
    assert 45 <= n <= 65  # ~190 B lines at 11520 B/s


def test_t104_reaches_the_ik_target_and_blocks():
    f = fw()
    f.receive(b'{"T":104,"x":300,"y":50,"z":150,"t":0.2,"r":0,"g":3.14,"spd":0.25}\n', 0.0)
    f.advance(5.0)
    fb = feedback(f, 5.0)
    assert fb.xyz == pytest.approx((300, 50, 150), abs=2.0)


def test_newer_build_queues_one_command_per_loop_and_fast_stop_matches_compact_bytes():
    f = Firmware(SimConfig(info_print=0, firmware="m3-2026"), t0=0.0)
    burst = b"".join(encode({"T": 102, "base": 0.01 * i, "shoulder": 0, "elbow": 1.57, "wrist": 0, "roll": 0,
                             "hand": 3.14, "spd": 0, "acc": 0}) for i in range(60))
    f.receive(burst, 0.0)
    f.advance(60 * 125 * BYTE + 0.01)
    assert b"Queue full" not in f.pop_output(10.0)  # the wire is slower than the loop: no backlog
    f2 = Firmware(SimConfig(info_print=0, firmware="m3-2026", loop_period=0.05), t0=0.0)  # a slow loop
    f2.receive(burst, 0.0)
    f2.advance(1.0)
    assert b'{"error":"Queue full"}' in f2.pop_output(1.0)
    f2.receive(b'{"T": 0}\n', 1.0)  # spaced JSON: not the fast path, just queued
    f2.advance(1.01)
    assert not f2.stop_flag
    f2.receive(b'{"T":0}\n', 1.01)
    f2.advance(1.06)  # the next pass of the slow loop
    assert f2.stop_flag and not f2._queue and f2.servos.torque().all()  # flushed, torque stays on


def test_a_fresh_line_after_a_torn_write_still_executes():
    f = fw()
    f.receive(b'{"T":102,"base":0.9,"shoul', 0.0)  # Ctrl-C tore this write
    f.receive(b"\n" + encode({"T": 102, "base": 0.3, "shoulder": 0, "elbow": 1.5708, "wrist": 0, "roll": 0,
                             "hand": math.pi, "spd": 0, "acc": 0}), 0.001)
    f.advance(0.5)
    assert feedback(f, 0.5).joints["base"] == pytest.approx(0.3, abs=2 * 2 * math.pi / 4096)


def test_t122_degrees_set_persistent_speed_that_t1041_uses_and_t102_clears():
    f = fw()
    # 90 deg/s -> calculatePosByDeg = 1024 steps/s; acc 10 -> 114 (100 steps/s^2 units)
    f.receive(encode({"T": 122, "b": 30, "s": -10, "e": 80, "t": 20, "r": -45, "h": 150, "spd": 90, "acc": 10}), 0.0)
    f.advance(0.02)
    assert f.servos.spd[0] == 1024 and f.servos.acc[0] == 114
    assert (f.move_spd, f.move_acc) == (1024, 114)
    f.advance(3.0)
    fb = feedback(f, 3.0)
    c = 2 * 2 * math.pi / 4096
    for key, deg in (("base", 30), ("shoulder", -10), ("elbow", 80), ("wrist", 20), ("roll", -45), ("hand", 150)):
        assert fb.joints[key] == pytest.approx(math.radians(deg), abs=c)
    # T:1041 moves with the stored moveSpd/moveAcc, not at full speed
    f.receive(b'{"T":1041,"x":300,"y":50,"z":150,"t":0.2,"r":0,"g":3.14}\n', 3.1)
    f.advance(3.2)
    assert f.servos.spd[0] == 1024 and f.servos.acc[0] == 114
    f.advance(6.0)
    assert feedback(f, 6.0).xyz == pytest.approx((300, 50, 150), abs=2.0)
    # a T:102 zeroes them: the next T:1041 runs at spd 0 (the servo maximum)
    f.receive(encode({"T": 102, "base": 0, "shoulder": 0, "elbow": 1.5708, "wrist": 0, "roll": 0, "hand": 3.14,
                      "spd": 500, "acc": 5}), 6.1)
    f.advance(9.0)
    assert (f.move_spd, f.move_acc) == (0, 0)
    f.receive(b'{"T":1041,"x":300,"y":0,"z":200,"t":0,"r":0,"g":3.14}\n', 9.0)
    f.advance(9.1)
    assert f.servos.spd[0] == 0 and f.servos.acc[0] == 0


def test_t121_moves_one_joint_in_degrees_and_acc_register_wraps_like_a_byte():
    f = fw()
    f.receive(b'{"T":121,"joint":4,"angle":-30,"spd":45,"acc":30}\n', 0.0)
    f.advance(0.02)
    assert f.servos.spd[3] == 512
    assert f.servos.acc[3] == round(30 / 360 * 4096) % 256  # 341 -> 85: the u8 register overflows above 22.4
    f.advance(2.0)
    assert feedback(f, 2.0).joints["wrist"] == pytest.approx(math.radians(-30), abs=2 * 2 * math.pi / 4096)


def test_codes_that_do_not_move_are_accepted_and_ignored():
    f = fw()
    before = f.servos.goal.copy()
    for line in (b'{"T":114,"led":255}', b'{"T":112,"mode":1,"b":60,"s":110,"e":50,"t":50,"r":50,"h":50}',
                 b'{"T":502,"id":254}', b'{"T":222,"name":"boot","step":"{\\"T\\":1,\\"mode\\":0}"}', b'{"T":401,"cmd":3}',
                 b'{"T":12345}'):
        f.receive(line + b"\n", 0.0)
    f.advance(0.5)
    assert (f.servos.goal == before).all() and f.servos.torque().all()
    assert f.pop_output(0.5) == b""


def test_a_question_to_a_stalled_simulator_process_fails_instead_of_waiting_for_ever(monkeypatch):
    """The simulator's child process stopped (SIGSTOP: it holds its state but runs nothing) must not hold its
    caller: the question fails after the bound, naming that the process is still there, and the process is ended
    (its late answer would otherwise be taken for the next question's)."""
    import contextlib
    import os
    import signal

    from roarmctl.device import simulator
    from roarmctl.device.simulator import PtySimulator

    monkeypatch.setattr(simulator, "ASK_TIMEOUT", 0.5)
    with PtySimulator(SimConfig(), process=True) as sim:
        os.kill(sim._proc.pid, signal.SIGSTOP)
        try:
            with pytest.raises(RuntimeError, match=r"gave no answer to 'executed' within 0.5 s \(still running\)"):
                sim.executed()
            assert not sim.alive()
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.kill(sim._proc.pid, signal.SIGCONT)


def test_a_simulator_process_that_died_is_one_error_and_stops_cleanly():
    """The simulator's process ended under the host (killed, out of memory): a question to it is one RuntimeError
    naming what was asked (an EOFError from the pipe before), and stop() then neither raises nor waits for it."""
    import time

    from roarmctl.device.simulator import PtySimulator, SimConfig

    sim = PtySimulator(SimConfig(), process=True).start()
    sim._proc.kill()
    sim._proc.join(5.0)
    with pytest.raises(RuntimeError, match="'recording'"):
        sim.recording()
    t = time.monotonic()
    sim.stop()
    assert not sim.alive() and time.monotonic() - t < 5.0
