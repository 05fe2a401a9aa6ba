"""Joint-space path planning with OMPL around a ``CollisionChecker``.

``plan_joint_path(checker, q_start, q_goal)`` returns a collision-free path (K, arm_dof): the
straight segment when it is valid (no OMPL call), else the planner's path, simplified and
densified. Every segment between consecutive waypoints is valid when checked at ``resolution``
(rad, Euclidean norm over the arm joints); the first and last rows are exactly q_start, q_goal.

Every motion the planner considers goes through ``CollisionChecker.segment_valid`` (a batched,
refined check of the whole segment, installed as OMPL's MotionValidator). Simplification is ours,
not OMPL's: OMPL's partialShortcutPath checks new segments state by state on its own grid, outside
the motion validator, so instead a greedy vertex reduction and seeded random shortcuts run through
``segment_valid`` too.

Determinism: OMPL's global seed is set before anything random is created; planners stop on a
count of state checks (``SOLVE_CHUNK_CHECKS`` per solve call, at most ``max_checks`` in all: the
same on any machine) rather than on the clock; shortcutting makes a fixed number of attempts from a
numpy generator seeded with the same seed. The time budgets are safety ceilings only: hitting one
raises ``CeilingError`` instead of returning a different path, so the same seed gives the same path
on any machine or an error, never another result. PRM is the exception: OMPL grows its roadmap in
one thread while another looks for a solution, so its result depends on thread timing.

OMPL is imported inside the functions (heavy import; ``roarmctl --help`` must stay fast).
"""

from __future__ import annotations

import bisect
import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError, PlanningError
from roarmctl.motion.collision import CollisionChecker, densify

if TYPE_CHECKING:
    import ompl.base

PLANNERS = ("RRTConnect", "RRTstar", "BITstar", "PRM", "KPIECE1")
# Work budgets in single-state checks (deterministic, unlike the clock). Planners that stop at their
# first solution get large chunks; the anytime ones (RRTstar, BITstar) refine until the chunk ends.
SOLVE_CHUNK_CHECKS = {"RRTConnect": 200_000, "KPIECE1": 200_000, "PRM": 200_000, "RRTstar": 5_000, "BITstar": 3_000}
MAX_SOLVE_CHECKS = 2_000_000  # default work budget of one solve (state checks); ~1 min of checking
RRTCONNECT_RANGE = 0.1  # RRTConnect's longest edge, as a fraction of the joint space's extent (OMPL's default: 0.2)
SHORTCUT_ATTEMPTS = 40  # default of plan_joint_path(simplify_attempts=...)
SHORTCUT_PATIENCE = 12  # stop shortcutting after this many attempts in a row that changed nothing


class CeilingError(PlanningError):
    """A wall-clock safety ceiling was hit (exit 3). Raised instead of returning whatever was found
    by then, so that the result never depends on how busy the machine is."""


def _ceiling_error(what: str, seconds: float, key: str) -> CeilingError:
    return CeilingError(f"{what} stopped at its wall-clock safety ceiling of {float(seconds)!r} s ({key})",
                        f"the machine is slow or busy: raise {key} (a ceiling only; the result does not depend on it)")


@dataclass
class PlanStats:
    """What one ``plan_joint_path`` call did. Times in s; ``checks`` counts single states checked."""

    planner: str
    direct: bool = False  # the straight segment was valid: OMPL was not called
    solve_time: float = 0.0
    simplify_time: float = 0.0
    total_time: float = 0.0
    checks: int = 0
    iterations: int = 0
    raw_waypoints: int = 0  # states in the planner's path before simplification
    waypoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # simplified, before densifying
    length: float = 0.0  # joint-space length of the returned path (rad)


def _fmt(q: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in q) + "]"


def _allocate(name: str, si: ompl.base.SpaceInformation) -> ompl.base.Planner:
    from ompl import geometric as og

    if name == "RRTConnect":
        # Half OMPL's default range (a fifth of the space's extent): with shorter edges the trees follow the free
        # space more closely, so the raw paths are shorter and fewer long motions fail. Measured on the wall and
        # post queries of bench/bench_vs_mplib.py, seeds 0-199, three tries + shortcutting as the pipeline does:
        # median path length -6..-16 %, motion duration -2..-9 %, and 14-30 % fewer state checks.
        planner = og.RRTConnect(si)
        planner.setRange(RRTCONNECT_RANGE * si.getStateSpace().getMaximumExtent())
        return planner
    if name == "RRTstar":
        # OMPL's default range (a fifth of the space's extent, ~2 rad here) makes every rewiring
        # motion long and the single tree slow to reach a goal beside an obstacle; measured on the
        # example scene, 0.5 rad and a 10 % goal bias solve 5 of 5 seeds in under 1 s (default: 3 of 5 in 3 s).
        planner = og.RRTstar(si)
        planner.setRange(0.5)
        planner.setGoalBias(0.1)
        return planner
    if name == "BITstar":
        return og.BITstar(si)
    if name == "PRM":
        return og.PRM(si)
    if name == "KPIECE1":
        return og.KPIECE1(si)
    raise AssertionError(name)


_SEGMENT_VALIDATOR = None  # the MotionValidator subclass, made at the first OMPL plan (class creation costs ~60 us)


def _segment_validator(si: ompl.base.SpaceInformation, checker: CollisionChecker, n: int,
                       resolution: float) -> ompl.base.MotionValidator:
    """OMPL's MotionValidator for ``si`` that checks a whole motion in one ``checker.segment_valid`` call."""
    global _SEGMENT_VALIDATOR
    if _SEGMENT_VALIDATOR is None:
        from ompl import base as ob

        class SegmentValidator(ob.MotionValidator):
            """Checks a whole motion in one batched call (the pre-filter and FK run once per segment)."""

            def checkMotion(self, s1: ompl.base.State, s2: ompl.base.State) -> bool:  # noqa: N802 (OMPL's name)
                n = self.n
                a = np.array([s1[i] for i in range(n)])
                b = np.array([s2[i] for i in range(n)])
                return bool(self.checker.segment_valid(a, b, self.resolution))

        _SEGMENT_VALIDATOR = SegmentValidator
    validator = _SEGMENT_VALIDATOR(si)
    validator.checker, validator.n, validator.resolution = checker, n, resolution
    return validator


def step_lengths(path: np.ndarray) -> np.ndarray:
    """Euclidean lengths (K - 1,) of the steps between consecutive rows of ``path`` (K, n) float: the numbers of
    ``np.linalg.norm(np.diff(path, axis=0), axis=1)`` (its own sum for real rows), without its wrapper's checks,
    which cost more than the sum on a path of a few rows (~15 calls a plan)."""
    d = path[1:] - path[:-1]
    return np.sqrt(np.add.reduce(d * d, axis=1))


def _drop_vertices(checker: CollisionChecker, path: np.ndarray, resolution: float) -> np.ndarray:
    """Greedy: from each kept vertex, jump to the farthest later vertex reachable in a straight line."""
    keep = [0]
    i = 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1 and not checker.segment_valid(path[i], path[j], resolution):
            j -= 1
        keep.append(j)
        i = j
    return path[keep]


def _random_shortcuts(checker: CollisionChecker, path: np.ndarray, resolution: float,
                      rng: np.random.Generator | None, attempts: int, ceiling: float, pruned: bool = False) -> np.ndarray:
    """Classic random shortcutting through ``checker.segment_valid`` (so every new segment gets the
    same refined check): join two random points of the path by a straight segment when it is
    valid and shorter, after the greedy vertex pass (``_drop_vertices``; not with ``pruned``: the path is that
    pass's result already). A fixed number of attempts from a seeded generator (None when ``attempts`` is 0);
    ``ceiling`` (s of wall time) is a safety stop that raises ``CeilingError``."""
    until = time.perf_counter() + ceiling
    if not pruned:
        path = _drop_vertices(checker, path, resolution)
    failures = 0
    changed = False
    # of the current path (recomputed only when a shortcut changes it: stale)
    seg: list[float] = []
    cum: list[float] = []
    rows: list[list[float]] = []
    stale = True
    # The draws of rng.uniform(0.0, c, 2) at each attempt, made at once: uniform is low + (high - low) * next_double,
    # the doubles that random() gives in the same order (the generator is not used afterwards).
    draws = rng.random(2 * attempts).tolist() if attempts > 0 and rng is not None else []
    for k in range(0, 2 * attempts, 2):
        if time.perf_counter() > until:
            raise _ceiling_error("path shortcutting", ceiling, "planner.simplify_budget")
        if len(path) < 3 or failures >= SHORTCUT_PATIENCE:
            break
        failures += 1
        if stale:  # as Python floats: the same numbers, cheaper to pick from (bisect for searchsorted)
            seg = step_lengths(path).tolist()
            cum = list(itertools.accumulate(seg, initial=0.0))  # np.cumsum's sums: one after the other
            rows = path.tolist()
            stale = False
        ta, tb = 0.0 + cum[-1] * draws[k], 0.0 + cum[-1] * draws[k + 1]
        if tb < ta:
            ta, tb = tb, ta
        ia = min(bisect.bisect_right(cum, ta) - 1, len(seg) - 1)
        ib = min(bisect.bisect_right(cum, tb) - 1, len(seg) - 1)
        if ia == ib:
            continue
        # path[i] + (path[i + 1] - path[i]) * s, one float at a time (the same operations as numpy's)
        sa, sb = (ta - cum[ia]) / seg[ia], (tb - cum[ib]) / seg[ib]
        pa = np.array([x + (y - x) * sa for x, y in zip(rows[ia], rows[ia + 1])])
        pb = np.array([x + (y - x) * sb for x, y in zip(rows[ib], rows[ib + 1])])
        gap = pb - pa
        if math.sqrt(gap.dot(gap)) >= (tb - ta) - 1e-6:  # np.linalg.norm's own sum for a vector
            continue
        # The pieces left of the two cut segments are re-checked too: a sub-segment is sampled on
        # a different grid than the segment it came from.
        if (checker.segment_valid(pa, pb, resolution) and checker.segment_valid(path[ia], pa, resolution)
                and checker.segment_valid(pb, path[ib + 1], resolution)):
            path = np.vstack([path[:ia + 1], pa, pb, path[ib + 1:]])
            failures = 0
            changed = True
            stale = True
    if changed:  # else a second pass would keep every vertex: the first one found each farther one unreachable
        path = _drop_vertices(checker, path, resolution)
    # Remove vertices that coincide (a shortcut ending on a vertex).
    keep = np.concatenate([[True], step_lengths(path) > 1e-9])
    keep[-1] = True
    return path[keep]


def simplify_path(checker: CollisionChecker, path: npt.ArrayLike, *, seed: int = 0, resolution: float = 0.01,
                  attempts: int = SHORTCUT_ATTEMPTS, time_budget: float = 5.0, pruned: bool = False) -> np.ndarray:
    """Shorten a valid joint path (K, arm_dof): greedy vertex removal plus ``attempts`` seeded random
    shortcuts, every new segment checked with ``checker.segment_valid`` at ``resolution`` (rad).
    The endpoints are kept exactly. E.g. plan several raw paths with ``simplify_attempts=0``, keep
    the shortest, and simplify only that one. ``time_budget`` (s) is a safety ceiling: past it,
    ``CeilingError``; the result depends only on the path, ``seed`` and ``attempts``.

    ``pruned``: ``path`` is what ``plan_joint_path_with_stats(simplify_attempts=0, max_step=None)`` returned with this
    checker in the same state, i.e. the greedy pass's result already; the pass is not run again, which gives the same
    path: from each kept vertex the first pass found the next kept one the farthest reachable and every later vertex
    unreachable (those segments are checked again alike, and the next vertex is taken unchecked), and a vertex the
    pass's de-duplication dropped only brings the one after it next (~5 failing segment checks a plan on b)."""
    path = np.array(path, dtype=float)
    return _random_shortcuts(checker, path, resolution, np.random.default_rng(seed), attempts, time_budget, pruned)


def plan_joint_path_with_stats(checker: CollisionChecker, q_start: npt.ArrayLike, q_goal: npt.ArrayLike, *,
                               planner: str = "RRTConnect",
                               time_budget: float = 10.0, simplify_budget: float = 5.0, seed: int = 0,
                               resolution: float = 0.01, max_step: float | None = 0.1,
                               try_direct: bool = True, simplify_attempts: int = SHORTCUT_ATTEMPTS,
                               max_checks: int = MAX_SOLVE_CHECKS) -> tuple[np.ndarray, PlanStats]:
    """Plan a collision-free joint-space path from ``q_start`` to ``q_goal`` (arm_dof,), rad.

    Returns (path (K, arm_dof), PlanStats). Work budgets decide the result: ``max_checks`` state
    checks for the planner, ``simplify_attempts`` shortcuts. ``time_budget`` and ``simplify_budget``
    (s of wall time) are safety ceilings that raise ``CeilingError``. ``resolution`` (rad) is the
    motion-checking step; ``max_step`` (rad) the largest gap between returned waypoints (None: only
    the simplified waypoints).
    Raises InputError for an unknown planner or bad vectors, PlanningError when start or goal is
    invalid or no path was found within the work budget, CeilingError (a PlanningError) at a ceiling.
    """
    if planner not in PLANNERS:
        raise InputError(f"unknown planner '{planner}'", f"valid planners: {', '.join(PLANNERS)}")
    robot = checker.robot
    n = robot.arm_dof
    q_start = np.asarray(q_start, dtype=float).reshape(-1)
    q_goal = np.asarray(q_goal, dtype=float).reshape(-1)
    for label, q in (("start", q_start), ("goal", q_goal)):
        if q.shape != (n,):
            raise InputError(f"{label} configuration must have {n} arm joint values, got {q.shape[0]}")
    if not (resolution > 0 and time_budget > 0 and simplify_budget >= 0 and max_checks > 0):
        raise InputError("resolution, time_budget and max_checks must be > 0 and simplify_budget >= 0")
    stats = PlanStats(planner=planner)
    t_total = time.perf_counter()
    checks0 = checker.check_count
    for label, q in (("start", q_start), ("goal", q_goal)):
        if not checker.is_valid(q):
            raise PlanningError(f"{label} configuration {_fmt(q)} is invalid: {checker.explain(q)}",
                                "move the obstacle, or choose another pose")

    if try_direct and checker.segment_valid(q_start, q_goal, resolution):
        path = np.vstack([q_start, q_goal])
        stats.direct = True
        stats.waypoints = path.copy()
        stats.raw_waypoints = 2
    else:
        path = _plan_ompl(checker, q_start, q_goal, planner, time_budget, simplify_budget, seed, resolution,
                          simplify_attempts, max_checks, stats)
    path = densify(path, max_step)
    path[0], path[-1] = q_start, q_goal
    stats.length = float(np.sum(step_lengths(path)))
    stats.checks = checker.check_count - checks0
    stats.total_time = time.perf_counter() - t_total
    return path, stats


def plan_joint_path(checker: CollisionChecker, q_start: npt.ArrayLike, q_goal: npt.ArrayLike, *,
                    planner: str = "RRTConnect",
                    time_budget: float = 10.0, simplify_budget: float = 5.0, seed: int = 0,
                    resolution: float = 0.01, max_step: float | None = 0.1,
                    simplify_attempts: int = SHORTCUT_ATTEMPTS, max_checks: int = MAX_SOLVE_CHECKS) -> np.ndarray:
    """Like ``plan_joint_path_with_stats`` but returns only the path (K, arm_dof)."""
    return plan_joint_path_with_stats(checker, q_start, q_goal, planner=planner, time_budget=time_budget,
                                      simplify_budget=simplify_budget, seed=seed, resolution=resolution,
                                      max_step=max_step, simplify_attempts=simplify_attempts,
                                      max_checks=max_checks)[0]


def _plan_ompl(checker: CollisionChecker, q_start: np.ndarray, q_goal: np.ndarray, planner: str,
               time_budget: float, simplify_budget: float, seed: int, resolution: float, simplify_attempts: int,
               max_checks: int, stats: PlanStats) -> np.ndarray:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    # Seed first: every RNG OMPL creates from here on (samplers, simplifier) draws from this seed.
    ou.RNG.setSeed(int(seed) if seed > 0 else int(seed) + 2**31 - 1 if seed < 0 else 1)
    n = q_start.size
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    lower, upper = checker._lower, checker._upper
    for i in range(n):
        bounds.setLow(i, float(lower[i]))
        bounds.setHigh(i, float(upper[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)

    buf = np.empty(n)

    def to_np(state: ompl.base.State) -> np.ndarray:
        for i in range(n):
            buf[i] = state[i]
        return buf

    def state_valid(state: ompl.base.State) -> bool:
        return checker.is_valid(to_np(state))

    si.setStateValidityChecker(state_valid)
    validator = _segment_validator(si, checker, n, resolution)
    si.setMotionValidator(validator)
    si.setStateValidityCheckingResolution(min(1.0, resolution / max(space.getMaximumExtent(), 1e-9)))
    si.setup()

    start, goal = space.allocState(), space.allocState()
    for i in range(n):
        start[i], goal[i] = float(q_start[i]), float(q_goal[i])
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(start, goal, 1e-9)
    objective = ob.PathLengthOptimizationObjective(si)
    if planner == "PRM":  # stop at the first solution (the default threshold 0 means "never satisfied")
        objective.setCostThreshold(ob.Cost(float("inf")))
    pdef.setOptimizationObjective(objective)
    algo = _allocate(planner, si)
    algo.setProblemDefinition(pdef)
    algo.setup()

    deadline = time.perf_counter() + time_budget
    chunk = SOLVE_CHUNK_CHECKS[planner]
    first_check = checker.check_count
    ceiling_hit = False

    def budget(n_checks: int) -> Callable[[], bool]:
        """Termination after ``n_checks`` more state checks (deterministic), or at the ceiling."""
        stop_at = checker.check_count + n_checks

        def fn() -> bool:
            nonlocal ceiling_hit
            stats.iterations += 1
            if time.perf_counter() > deadline:
                ceiling_hit = True
                return True
            return checker.check_count >= stop_at

        return ob.PlannerTerminationCondition(fn)

    t0 = time.perf_counter()
    while True:  # OMPL planners resume from their tree/graph on each solve() call
        if planner == "PRM":
            # PRM evaluates the termination condition in a second thread: a Python callable there
            # would deadlock on the GIL, so it gets OMPL's own (C++) timed condition.
            algo.solve(ob.timedPlannerTerminationCondition(max(deadline - time.perf_counter(), 1e-3)))
            ceiling_hit = not pdef.hasExactSolution() and time.perf_counter() > deadline
        else:
            algo.solve(budget(min(chunk, max(max_checks - (checker.check_count - first_check), 1))))
        if ceiling_hit:  # whatever was found by now depends on the clock: never return it
            stats.solve_time = time.perf_counter() - t0
            raise _ceiling_error(f"the {planner} search from {_fmt(q_start)} to {_fmt(q_goal)}", time_budget,
                                 "planner.time_budget")
        if pdef.hasExactSolution() or checker.check_count - first_check >= max_checks:
            break
    stats.solve_time = time.perf_counter() - t0
    if not pdef.hasExactSolution():
        raise PlanningError(
            f"no collision-free path from {_fmt(q_start)} to {_fmt(q_goal)} within {max_checks} state checks ({planner})",
            "raise planner.max_checks or move the obstacle",
        )
    path = og.PathGeometric(pdef.getSolutionPath())
    stats.raw_waypoints = path.getStateCount()

    t0 = time.perf_counter()
    out = np.array([[st[i] for i in range(n)] for st in path.getStates()])
    out[0], out[-1] = q_start, q_goal
    rng = np.random.default_rng(seed) if simplify_attempts > 0 else None  # none drawn without attempts (~25 us to make)
    out = _random_shortcuts(checker, out, resolution, rng, simplify_attempts, simplify_budget)
    stats.simplify_time = time.perf_counter() - t0
    stats.waypoints = out.copy()
    return out
