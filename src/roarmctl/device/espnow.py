"""The arm's ESP-NOW mode as found when roarmctl connects, so that it can be given back when the link closes.

The firmware starts in follower mode (``espNowMode = 3``, ``RoArm-M3_config.h`` line 16 of Waveshare's 0.84 example;
the 20260701 build alike) and its flash mission ``boot`` may change that with a ``{"T":301,"mode":M}`` step (set-up:
``RoArm-M3_example.ino`` lines 147-148 play it). Connecting leaves the mode (``{"T":301,"mode":0}``) so that no leader
nearby drives the arm during a run; without giving it back a follower set-up stayed off until the next reboot.

No command reports the mode itself. What can be read is the boot mission: the firmware lists it when it plays it at
start-up and on ``{"T":602}`` (``missionContent("boot")``, ``RoArm-M3_advance.h`` lines 33-62: ``[StepNum: N ] -``
and the step's JSON, one a line, then a line ending ``.mission ends. ^^^ ^^^ ^^^``; ``file not found.`` without one).
The mode found is the boot mission's last ``T:301`` step, else the firmware's default; a mode set since by another
client (the web page) is not readable, and ``source`` says so.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

#: espNowMode's values (``json_cmd.h``: 0 none, 1 flow-leader (group), 2 flow-leader (single), 3 follower).
MODE_NAMES = {0: "none", 1: "flow-leader (group)", 2: "flow-leader (single)", 3: "follower"}
DEFAULT_MODE = 3  # RoArm-M3_config.h: espNowMode = 3, "[default]follower"
BOOT_MISSION_INFO = {"T": 602}  # json_cmd.h CMD_BOOT_MISSION_INFO: missionContent("boot")
_STEP = re.compile(r"^\[StepNum:\s*\d+\s*\]\s*-\s*(.*)$")
_LISTING_END = re.compile(r"reading file: boot\.mission ends")
_NOT_FOUND = "file not found."


@dataclass(frozen=True)
class EspNowMode:
    """The ESP-NOW mode found at connect (0-3) and, in a few words, how it was found."""

    mode: int
    source: str

    def as_dict(self) -> dict[str, Any]:
        """The execution log's ``device.esp_now``."""
        return {"found": self.mode, "name": MODE_NAMES[self.mode], "source": self.source}


def boot_mission_listing(steps: Iterable[str]) -> list[str]:
    """What ``missionContent("boot")`` prints for a boot mission of ``steps`` (JSON lines): a header, the mission's
    intro line, each step, the end line (``RoArm-M3_advance.h`` lines 40-59). The firmware simulator prints it."""
    return ["---=== File Content ===---", "reading file: [boot] starts:\n",
            '{"name":"boot","intro":"these cmds run automatically at boot."}',
            *(f"[StepNum: {n} ] - {step}" for n, step in enumerate(steps, 1)),
            "^^^ ^^^ ^^^ reading file: boot.mission ends. ^^^ ^^^ ^^^"]


def listing_ended(lines: Iterable[str]) -> bool:
    """Whether ``lines`` (text the firmware printed) hold the end of a boot mission listing, or its absence."""
    return any(_LISTING_END.search(s) or s.strip() == _NOT_FOUND for s in lines)


def mode_from_listing(lines: Iterable[str], where: str) -> EspNowMode | None:
    """The mode the boot mission listed in ``lines`` sets (its last valid ``T:301`` step), the default when it sets
    none, or None when ``lines`` hold no complete listing. ``where``: how the listing was read, for ``source``."""
    mode: int | None = None
    ended = False
    for s in lines:
        s = s.strip()
        if _LISTING_END.search(s) or s == _NOT_FOUND:
            ended = True
            continue
        m = _STEP.match(s)
        if m is None:
            continue
        try:
            step = json.loads(m.group(1))
        except ValueError:
            continue  # the firmware skips a step it cannot parse too
        if isinstance(step, dict) and step.get("T") == 301 and type(step.get("mode")) is int and step["mode"] in MODE_NAMES:
            mode = step["mode"]
    if not ended:
        return None
    if mode is None:
        return EspNowMode(DEFAULT_MODE, f"the firmware's default (its boot mission, {where}, sets none)")
    return EspNowMode(mode, f"the boot mission's T:301 step ({where})")


def unread() -> EspNowMode:
    """The mode assumed when the boot mission could not be read: the firmware's default."""
    return EspNowMode(DEFAULT_MODE, "the firmware's default (the boot mission could not be read)")
