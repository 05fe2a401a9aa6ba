"""Start-up: what the CLI does NOT load (import graphs, not clocks: the figures are in bench/bench_startup.py)."""

from __future__ import annotations

import subprocess
import sys


def _imported(code: str) -> set[str]:
    """Modules imported by running ``code`` in a fresh interpreter (from -X importtime)."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return {line.rsplit("|", 1)[-1].strip() for line in proc.stderr.splitlines() if line.startswith("import time:")}


def test_help_loads_no_numeric_or_planning_library():
    mods = _imported("import sys; sys.argv = ['roarmctl', '--help']\n"
                     "from roarmctl.launch import main\ntry:\n    main()\nexcept SystemExit:\n    pass")
    assert "roarmctl.cli" in mods
    assert not mods & {"numpy", "ompl", "fcl", "toppra", "matplotlib", "scipy"}


def test_toppra_for_planning_defers_pyplot_and_pyplot_still_works():
    code = ("import sys\nfrom roarmctl.motion.timing import import_toppra\nta = import_toppra()\n"
            "assert ta.algorithm.TOPPRA and ta.SplineInterpolator\n"
            "assert 'matplotlib.figure' not in sys.modules and 'matplotlib.rcsetup' not in sys.modules\n"
            "import matplotlib.pyplot as plt\nfig = plt.figure()\n"
            "assert type(fig).__name__ == 'Figure' and 'matplotlib.figure' in sys.modules\n"
            "import matplotlib\nassert matplotlib.rcParams['figure.dpi'] > 0")
    mods = _imported(code)
    assert "toppra" in mods and "scipy.interpolate" in mods
