"""Hostile inputs (issue 19): the corpus that tests/test_trust.py checks case by case and tests/test_fuzz.py
runs through the CLI. Each builder writes files into a folder and returns the path(s) to hand to roarmctl.

The code-execution payload is real: under ``--trust-xacro`` (xacro's own evaluation) it runs
``touch MARKER``; everywhere else the marker must never appear.
"""

from __future__ import annotations

import builtins
import json
import math
import os
from pathlib import Path

import yaml

from roarmctl.robot.loader import bundled_dir, load_robot

XACRO_NS = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'
M3_Q = ["0", "0", "1.57", "0", "0", "0"]


def payload(marker: Path) -> str:
    """A ``${...}`` that runs ``touch marker`` through xacro 2.1.1's ``eval``: the dunder names sit inside
    the comprehension's own scope, which xacro's filter on names starting with ``__`` does not inspect."""
    return ("str([x for c in [()] for b in [c.__class__.__base__] for s in b.__subclasses__() "
            "if s.__name__ == 'catch_warnings' "
            f"for x in [s()._module.__builtins__['__import__']('os').system('touch {marker}')]])")


def m3_xacro(folder: Path, name_expr: str = "'roarm_m3_pro'", extra: str = "", file: str = "arm.xacro") -> Path:
    """The bundled RoArm-M3 Pro URDF as a xacro whose robot name is ``${name_expr}``, with ``extra`` XML
    (properties, macros, includes) first inside ``<robot>``."""
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
    # the name is set by an element after ``extra``, so that the properties it defines exist by then
    urdf = urdf.replace('<robot name="roarm_m3_pro">', f'<robot {XACRO_NS}>{extra}<xacro:attribute name="name" '
                        f'value="${{{name_expr}}}"/>', 1)
    path = folder / file
    path.write_text(urdf)
    return path


def sidecar(folder: Path, urdf: str, **extra) -> Path:
    """The bundled M3 sidecar pointing at ``urdf`` (relative to ``folder``), with ``extra`` fields."""
    side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
    side["urdf"] = urdf
    side.update(extra)
    path = folder / "arm.yaml"
    path.write_text(yaml.safe_dump(side))
    return path


# --------------------------------------------------------------------------- bombs
POW_BOMB = "9**9**9"


def macro_doubling(levels: int = 20) -> str:
    """Macro k calls macro k-1 twice: 2**levels links from a file of a few kB."""
    macros = ['<xacro:macro name="m0"><link name="bomb"/></xacro:macro>']
    macros += [f'<xacro:macro name="m{k}"><xacro:m{k - 1}/><xacro:m{k - 1}/></xacro:macro>' for k in range(1, levels + 1)]
    return "".join(macros) + f"<xacro:m{levels}/>"


def block_doubling(levels: int = 20) -> str:
    """Block parameters passed on twice per level: a doubling through ``insert_block``."""
    macros = ['<xacro:macro name="b0" params="*x"><xacro:insert_block name="x"/></xacro:macro>']
    macros += [f'<xacro:macro name="b{k}" params="*x"><xacro:b{k - 1}><g><xacro:insert_block name="x"/>'
               f'<xacro:insert_block name="x"/></g></xacro:b{k - 1}></xacro:macro>' for k in range(1, levels + 1)]
    return "".join(macros) + f'<xacro:b{levels}><link name="blk"/></xacro:b{levels}>'


def string_doubling(levels: int = 60) -> str:
    """Property k is property k-1 twice: a string of 2**levels characters."""
    props = ['<xacro:property name="p0" value="xxxxxxxx"/>']
    props += [f'<xacro:property name="p{k}" value="${{p{k - 1}+p{k - 1}}}"/>' for k in range(1, levels + 1)]
    return "".join(props) + f'<link name="${{p{levels}}}"/>'


#: Expressions that build something huge from a few characters (issue 19 review): each must stop on a bound
#: (a size checked before or as the value is made), not in memory. Name -> (expression, what the refusal says).
SIZE_BOMBS = {
    "string repetition": ("'a'*10**9", "repetition"),
    "list repetition": ("[0]*10**9", "repetition"),
    "integer power": ("2**10**8", "larger than 256 bits"),
    "float power": ("2.0**10**8", "out of range"),
    "nested parentheses": ("(" * 5000 + "1" + ")" * 5000, "nested"),
    "long expression": ("+".join(["1"] * 200_000), "an expression of more than"),
    "long list display": ("[" + ",".join(["1"] * 200_000) + "]", "an expression of more than"),
    "str of a shared list": ("str(['a'*1000000]*100000)", "prints as more than"),
    "shared list printed": ("len(str([[[0]*1000]*1000]*100))", "prints as more than"),
    "compare shared lists": ("[[0]*100000]*100000 == [[0]*100000]*100000", "prints as more than"),
    "repeated work on a property": ("'ab'", "characters to expand"),
}


def lexer_bomb(n: int = 1_000_000) -> str:
    """An attribute of ``n`` ``$a`` pieces: xacro's lexer copies the rest of the text after each piece."""
    return f'<foo a="{"$a" * n}"/>'


def macro_params_redos(n: int = 40) -> str:
    """A macro parameter default with an unclosed quote: xacro's pattern for it backtracks 2**n ways."""
    return f'<xacro:macro name="m" params="x:={"a" * n}\'"><foo/></xacro:macro><xacro:m/>'


def repeated_work(n: int = 2000) -> str:
    """A 1 MB string property compared ``n`` times: no value is made, each comparison reads 1 MB."""
    return ('<xacro:property name="big" value="${\'a\'*1000000}"/><xacro:property name="big2" value="${\'a\'*1000000}"/>'
            + "".join('<foo a="${big == big2}"/>' for _ in range(n)))


def self_include(folder: Path) -> Path:
    """A xacro that includes itself."""
    path = folder / "loop.xacro"
    path.write_text(f'<robot name="loop" {XACRO_NS}><xacro:include filename="loop.xacro"/></robot>')
    return path


def fifo(folder: Path, name: str) -> Path:
    """A named pipe nobody writes to: reading it would block forever."""
    path = folder / name
    os.mkfifo(path)
    return path


# --------------------------------------------------------------------------- trajectories and logs
def trajectory_doc(robot: str = "roarm_m3_pro") -> dict:
    """A valid ``roarmctl.trajectory/1`` document for the M3: a 0.6 s quintic move within its limits."""
    q0 = [0.0, 0.0, 1.5708, 0.0, 0.0, 0.0]
    q1 = [0.2, 0.1, 1.7, 0.0, 0.1, 0.2]
    dur, n = 0.6, 60
    pts = []
    for k in range(n + 1):
        u = k / n
        s = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
        ds = (30 * u ** 2 - 60 * u ** 3 + 30 * u ** 4) / dur
        dds = (60 * u - 180 * u ** 2 + 120 * u ** 3) / dur ** 2
        pts.append({"time_from_start": round(u * dur, 9), "positions": [a + s * (b - a) for a, b in zip(q0, q1)],
                    "velocities": [ds * (b - a) for a, b in zip(q0, q1)],
                    "accelerations": [dds * (b - a) for a, b in zip(q0, q1)]})
    return {"format": "roarmctl.trajectory/1", "robot": robot, "joint_names": load_robot("roarm_m3_pro").joint_names,
            "sample_rate": 100.0, "points": pts,
            "events": [{"time_from_start": 0.6, "kind": "grasp", "label": "cube", "position": [0.2, 0.0, 0.05]}],
            "segments": [{"start": 0.0, "end": 0.6, "kind": "free", "label": "move"}],
            "limits": {"velocity_scale": 0.5},
            "scene": {"items": [{"name": "cube", "role": "object", "shape": "box", "size": [0.04, 0.04, 0.04],
                                 "xyz": [0.25, -0.15, 0.02], "rpy": [0, 0, 0]}]},
            "plan": None, "singularity_margin": None}


def execlog_doc(robot: str = "roarm_m3_pro", n: int = 20) -> dict:
    """A small ``roarmctl.execlog/1`` document: n joint commands and n feedback lines, 20 ms apart."""
    sent, received = [], []
    for k in range(n):
        q = 0.01 * k
        cmd = {"T": 102, "base": q, "shoulder": 0.0, "elbow": 1.57, "wrist": 0.0, "roll": 0.0, "hand": math.pi - 0.2,
               "spd": 0, "acc": 10}
        sent.append({"t": round(0.02 * k, 6), "cmd": cmd})
        fb = {"T": 1051, "x": 300.0, "y": 0.0, "z": 200.0, "b": q, "s": 0.0, "e": 1.57, "t": 0.0, "r": 0.0,
              "g": math.pi - 0.2}
        received.append({"t": round(0.02 * k + 0.01, 6), "line": json.dumps(fb), "feedback": fb})
    return {"format": "roarmctl.execlog/1", "port": "sim", "firmware": "sim", "robot": robot, "strategy": "stream",
            "rate": 50.0, "speed_scale": 1.0, "t0_monotonic": 0.0, "duration": 0.02 * n, "summary": {},
            "notes": [], "tracking": [], "sent": sent, "received": received}


# --------------------------------------------------------------------------- every allowed xacro function
#: Property values the table below calls functions with (built once: making them is not what is tested).
def table_properties() -> dict:
    from roarmctl.robot.xacro_eval import MAX_INT_BITS, MAX_ITEMS, MAX_STR

    return {"big_i": 2 ** MAX_INT_BITS - 1, "big_s": "a" * MAX_STR, "spaces": "a " * (MAX_STR // 2),
            "big_l": [0.5] * (MAX_ITEMS // 10), "pairs": [[0, 1]] * 1000}


#: Arguments as an attacker writes them: extreme integers (digits, exponents, shifts), floats at the ends of
#: their range, the largest strings and lists a value may be, empty and odd types.
HOSTILE_ARGS = ("0", "-1", "10**9", "-10**9", "2**62", "-2**62", "big_i", "-big_i", "1e308", "-1e308", "5e-324",
                "inf", "-inf", "nan", "''", "'1'*80", "'9'*81", "big_s", "spaces", "[]", "big_l", "pairs",
                "{'a': 1}", "True", "None")
#: The ones that cost time to pass around (sized at each use): put beside one benign argument only.
BIG = ("big_s", "spaces", "big_l", "pairs")
#: Ordinary arguments the hostile one is put beside.
BENIGN_ARGS = ("1", "2.5", "'a b'", "[1.0, 2.0]")
#: The numeric ones, tried in every pair (``round(1, -10**9)``, ``ldexp(1e308, 10**9)``).
NUMERIC_ARGS = ("0", "-1", "10**9", "-10**9", "2**62", "-2**62", "big_i", "-big_i", "1e308", "-1e308", "5e-324", "inf",
                "-inf", "nan")


def hostile_calls() -> list[str]:
    """Expressions calling every allowed function and string method with hostile arguments: one to three
    arguments, a hostile one at each place beside benign ones, and every pair of numeric extremes."""
    from roarmctl.robot.xacro_eval import FUNCTIONS, STR_METHODS

    arg_lists: list[tuple[str, ...]] = [()]
    arg_lists += [(h,) for h in HOSTILE_ARGS + BENIGN_ARGS]
    arg_lists += [(h, b) for h in HOSTILE_ARGS for b in BENIGN_ARGS if h not in BIG or b == "1"]
    arg_lists += [(b, h) for h in HOSTILE_ARGS for b in BENIGN_ARGS if h not in BIG or b == "1"]
    arg_lists += [(a, b) for a in NUMERIC_ARGS for b in NUMERIC_ARGS]
    arg_lists += [("' '", h, "1") for h in HOSTILE_ARGS] + [("'a'", "'b'", h) for h in HOSTILE_ARGS]
    calls = [f"{name}({', '.join(args)})" for name in FUNCTIONS for args in arg_lists]
    owners = ("'a b a'", "big_s", "spaces", "''")
    calls += [f"{owner}.{name}({', '.join(args)})" for name in STR_METHODS for owner in owners for args in arg_lists
              if len(args) < 2 or owner == "'a b a'"]
    return calls


def evaluate_calls(calls: list[str]) -> dict:
    """Each call evaluated with a fresh budget: {"refused": n, "answered": n, "other": [call: exception]}, and
    every answer compared with Python's own (``differs``) where Python answers in bounded work too."""
    from roarmctl.robot.xacro_eval import Budget, Evaluator, Refused

    props = table_properties()
    tally: dict = {"refused": 0, "answered": 0, "other": [], "differs": []}
    for expr in calls:
        try:
            value = Evaluator(lambda n: props[n], Budget())(expr)
        except Refused:
            tally["refused"] += 1
            continue
        except Exception as exc:  # noqa: BLE001 - reported by the test
            tally["other"].append(f"{expr}: {type(exc).__name__}: {exc}")
            continue
        tally["answered"] += 1
        try:
            expected = eval(expr, {"__builtins__": {}}, {**props, **_python_names()})  # noqa: S307 - our own table
        except Exception:  # noqa: BLE001 - ours answered where Python refuses: a difference
            expected = "<python refused>"
        if repr(value) != repr(expected):
            tally["differs"].append(f"{expr}: {str(value)[:60]} != {str(expected)[:60]}")
    return tally


def _python_names() -> dict:
    import math as m

    from roarmctl.robot.xacro_eval import FUNCTIONS, MATH_FUNCTIONS

    return {**{n: getattr(builtins, n) for n in FUNCTIONS if n not in MATH_FUNCTIONS}, "inf": m.inf, "nan": m.nan,
            **{n: getattr(m, n) for n in MATH_FUNCTIONS}}
