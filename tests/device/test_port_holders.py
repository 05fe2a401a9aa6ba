"""Another process holding the port open without a lock is named in a warning (issue 13, finding 6)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from devtraj import HOME, min_jerk

from roarmctl.device.ports import port_holders
from roarmctl.device.simulator import PtySimulator, SimConfig

pytestmark = [pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc scan is Linux-only"),
              pytest.mark.slow]  # real time: execute on the simulated arm with a second holder

HOLDER = ("import os, sys, time\n"
          "open('/proc/self/comm', 'w').write('ModemManager')\n"
          "fd = os.open(sys.argv[1], os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)\n"
          "print('held', flush=True)\n"
          "time.sleep(60)\n")


def test_execute_warns_with_the_holders_name(tmp_path):
    p = tmp_path / "s.traj.json"
    min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.5]).save(p)
    with PtySimulator(SimConfig(), process=True) as sim:
        assert port_holders(sim.path) == []  # the simulator holds the master side: it is the device
        holder = subprocess.Popen([sys.executable, "-c", HOLDER, sim.path], stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout.readline().strip() == "held"
            assert (holder.pid, "ModemManager") in port_holders(sim.path)
            proc = subprocess.run([sys.executable, "-m", "roarmctl", "execute", str(p), "--port", sim.path, "--yes",
                                   "--json"], capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        finally:
            holder.kill()
            holder.wait()
        assert port_holders(sim.path) == []
    assert proc.returncode == 0, proc.stderr
    warn = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert len(warn) == 1 and f"process {holder.pid} (ModemManager)" in warn[0] and sim.path in warn[0]
