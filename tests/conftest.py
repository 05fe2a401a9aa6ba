"""Suite-wide set-up.

``make test`` runs the suite on every core (pytest-xdist, ``--dist loadgroup``: the browser-view tests share
one worker, ``tests/test_view.py``). The tests under ``tests/device/`` that stream to the firmware simulator in
real time are spread over the workers like any other test: the simulated firmware runs in a process of its own,
on its own clock and at the lowest real-time priority where the system allows it (as an ESP32 keeps its own
time), and the streamer compares the arm with the plan on the plan's own clock (it pauses where a busy host made a
tick so late that the next was due too: every tick is sent, in order, none skipped) and widens its tracking check
only by lateness it measured (late sends, late answers), so a busy machine, a second stream beside it included,
makes a run late, not wrong. Putting them all on one worker made their ~4 minutes the floor of the whole suite.
"""

from __future__ import annotations

import os

import pytest

# MuJoCo takes its GL back end from MUJOCO_GL when it is first imported, and a worker runs physics tests (which import
# it) before datagen's cameras as often as after: EGL for the whole session, as `make render` installs it, so the
# order of tests on a worker does not decide the back end (GLFW, the default, aborts the worker without a display).
os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(autouse=True)
def _scheduling_policy_unchanged():
    """Every test leaves its worker's scheduling policy as it found it. A library that makes the worker real-time
    (SVT-AV1 as root: SCHED_FIFO 99, roarmctl.export.lerobot.video) makes every process a later test starts on it
    real-time too: a busy-loop child then starves everything on its core and the run hangs. Named at the test that
    did it, not found an hour later in another."""
    if not hasattr(os, "sched_getscheduler"):
        yield
        return
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    yield
    after = (os.sched_getscheduler(0), os.sched_getparam(0))
    assert after == before, f"this test changed the worker's scheduling policy/priority from {before} to {after}"


#: Tests that take longest on their worker (wall, mostly waiting: real time on the simulated arm, Ray, CoACD), by
#: node id prefix, longest first, from ``make test``'s --durations at load 2-5 (seconds in the comments). Handed out
#: right after the browser-view group, they run beside the many short tests instead of after them: with
#: ``--dist loadgroup`` the last long test to start sets the run's wall time. A name that no longer exists does
#: nothing; a new long test belongs here (``make test`` prints its 15 slowest).
LONG_FIRST = (
    # its xdist group datagen-dataset96 with it: the fixture, the killed run's test, this one (63 at load 4)
    "tests/test_datagen.py::test_ray_tasks_write_the_same_dataset_as_the_process_pool",
    "tests/device/test_teach_e2e.py::test_taught_by_hand_planned_and_executed_passes_every_waypoint",  # 28
    "tests/test_readme_examples.py::test_readme_command[roarmctl datagen plans/datagen/pick_place.yaml -n 4 -o cubes",  # 23-32
    "tests/test_zone_properties.py::test_generated_plans_reach_their_targets",  # 7-17 each arm
    "tests/test_jaw_pieces.py::test_a_fresh_decomposition_is_the_bundled_file_byte_for_byte",  # 12
    "tests/device/test_where_the_arm_is.py::test_start_current_after_the_arm_was_moved_by_hand",  # 10
    "tests/device/test_physics_execute.py::test_a_lagging_arm_is_not_a_fault",  # 10 (load 2-10)
    "tests/device/test_physics_execute.py::test_the_default_strategy_follows_the_plan_on_the_physics_arm",  # 10
    "tests/device/test_streamer.py::test_a_host_stall_in_a_detour_makes_the_run_late_never_cut_across_the_obstacle",  # 10
    "tests/device/test_physical_ranges.py::test_waveshares_sdk_sequence_leaves_no_physical_range_on_sim_device",  # 9
    "tests/device/test_execute.py::test_sim_run_follows_the_plan_and_keeps_time",  # 9
    "tests/test_scene_files.py::test_a_plan_file_with_a_mesh_and_a_cloud_plans_and_draws",  # 8
    "tests/test_trust_xacro.py::test_every_allowed_function_with_hostile_arguments",  # 9 (load 2-10)
    "tests/test_yaml_reader.py::test_generated_documents_read_as_pyyaml_reads_them",  # 8
    "tests/test_physics.py::test_the_0_2_kg_weight_holds_its_sag",  # 8
    "tests/device/test_startup_stop.py::test_ctrl_c_while_connect_waits_for_set_up_sends_nothing_and_logs",  # 7
    "tests/test_doc_python_blocks.py::test_the_block_runs_as_written[docs/guide.md",  # 1-10 each (those that plan)
)


def _hand_out_rank(item: pytest.Item) -> int:
    """0 for the browser-view group, 1 + the place in ``LONG_FIRST`` for a long test, after them all the rest."""
    if any(m.args == ("browser-view",) for m in item.iter_markers("xdist_group")):
        return 0
    return 1 + next((k for k, prefix in enumerate(LONG_FIRST) if item.nodeid.startswith(prefix)), len(LONG_FIRST))


@pytest.hookimpl(tryfirst=True)  # before -m "not slow" deselects
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """A test that starts the headless browser (the ``chromium`` fixture of tests/test_view.py) is slow: left out
    of ``make test-fast``; the browser-view group goes first, then the known long tests (``LONG_FIRST``)."""
    for item in items:
        if "chromium" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.slow)
    # The browser-view tests are one xdist group (one worker, about two minutes of mostly waiting on Chromium): handed
    # out first, they run beside the rest instead of after it (collected last, they were the suite's tail). The order
    # is xdist's only with --no-loadscope-reorder (the Makefile's): by default loadgroup hands out the groups with the
    # most tests first, and every single test after all of them.
    items.sort(key=_hand_out_rank)


@pytest.fixture
def virtual_sim():
    """``execute --sim`` (in this process) and ``roarmctl.api.execute(sim=True)`` run on a virtual clock for the test
    (``clirun.virtual_simulator``): the simulator's firmware and servo models behind the real ``Link``, no pty and no
    real time, so a test of what a run does costs its computation only and its numbers are the same on an idle or a
    busy machine. The pty and real time keep their own tests (tests/device/test_execute.py, marked slow).
    Returns the simulators made, in order (their ``recording()`` is the witness of where the arm went)."""
    from clirun import virtual_simulator

    with virtual_simulator() as made:
        yield made
