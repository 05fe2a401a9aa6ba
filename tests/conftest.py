"""Suite-wide set-up: the tests that run the simulated arm share one xdist worker.

``make test`` runs the suite on every core (pytest-xdist, ``--dist loadgroup``); the tests under
``tests/device/`` stream to the firmware simulator on a pseudo-terminal in real time, so they go to one
worker, one after the other, and two of them never compete for the same cores.
"""

from __future__ import annotations

from pathlib import Path

import pytest

DEVICE = Path(__file__).resolve().parent / "device"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Put every test of tests/device/ in the xdist group ``simulated-arm``."""
    for item in items:
        if DEVICE in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.xdist_group("simulated-arm"))
