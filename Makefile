# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: all demo test test-fast fuzz lint bench clean install browser render

all: test

# The install compiles the C kernel (FK, dynamics and state checker) into the source tree (editable install):
# a change to the C source needs a new install too.
$(STAMP): pyproject.toml setup.py src/roarmctl/_kernel.c src/roarmctl/_kernel_jerk.c
	$(PYTHON) -m venv $(VENV)
	rm -f src/roarmctl/*.so src/roarmctl/motion/*.so roarmctl/*.so  # an older build's module would shadow the new abi3 one
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

# The whole suite on every core (pytest-xdist; the browser-view tests share one worker; the real-time
# simulated-arm tests spread over the workers like the rest: tests/conftest.py says why that is safe).
# TEST_JOBS: the number of xdist workers (a number, or auto: one per core). Two per core by default: the
# real-time tests mostly wait (on the simulated arm's clock, on Chromium), and a second worker per core fills
# those waits (idle, 2 cores: 256 s with one worker per core, 202 s with two; docs/design.md "Tests").
TEST_JOBS ?= $(shell echo $$(( 2 * $$(nproc 2>/dev/null || echo 1) )))
# --durations: the 15 slowest tests are printed at the end, so one over ~5 s that lacks @pytest.mark.slow is seen.
# PYTHONDONTWRITEBYTECODE emptied: pytest keeps each test module's assertion-rewritten bytecode in __pycache__ (git
# ignores it); with the variable set (as some shells and images do) every worker of every run rewrote all ~110
# test modules again (collection: 7.2 s of CPU per worker, 3.1 s with the bytecode kept).
# --no-loadscope-reorder: the workers get the tests in tests/conftest.py's order (the browser-view group, then the
# known long tests, then the rest), not xdist's default of the largest groups first and every single test after them.
test: $(STAMP) render
	PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest -n $(TEST_JOBS) --dist loadgroup --no-loadscope-reorder --durations=15

# The inner loop (under 30 s on 2 idle cores): the unit and differential tests, each under ~0.3 s of CPU on its own
# (set-up shared with its module aside); left out, marked @pytest.mark.slow: a test over that, real-time runs on the
# simulated arm, physics runs, the browser, fresh interpreters, property sweeps (docs/design.md "Tests"). One worker
# per core: nothing in it waits, so a second worker per core would only import and collect everything again.
FAST_JOBS ?= $(shell nproc 2>/dev/null || echo 1)
test-fast: $(STAMP) render
	PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest -n $(FAST_JOBS) --dist loadgroup --no-loadscope-reorder -m "not slow"

# Lint and types (rules and why: pyproject.toml, docs/design.md "Lint and types"): ruff over everything that is
# Python (the package, its tests, benches and examples); mypy over the package and the examples users copy from.
lint: $(STAMP)
	$(BIN)/ruff check src tests bench examples
	$(BIN)/mypy
	$(BIN)/mypy examples

# Chromium from the system's packages, for the browser-view tests (tests/test_view.py: Playwright drives
# /usr/bin/chromium; nothing is downloaded by Playwright). Installs with apt-get when missing (needs root, as
# CI has); on your own machine: sudo apt-get install chromium (Debian/Ubuntu), or set ROARMCTL_CHROMIUM.
browser:
	@if command -v chromium >/dev/null 2>&1; then echo "chromium: $$(command -v chromium)"; \
	else apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; fi

# Offscreen rendering for datagen's cameras (src/roarmctl/physics/render.py): MuJoCo through EGL on Mesa's
# llvmpipe (CPU), from the system's packages. Installs with apt-get when missing (needs root, as CI has); on your
# own machine: sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri (Debian/Ubuntu).
RENDER_PACKAGES := libegl1 libegl-mesa0 libgl1-mesa-dri
render:
	@if [ "$$(dpkg-query -W -f='$${Status}\n' $(RENDER_PACKAGES) 2>/dev/null | grep -c 'ok installed')" = "3" ]; \
	then echo "EGL: $(RENDER_PACKAGES) installed"; \
	else apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(RENDER_PACKAGES); fi

# The fuzz suite's CI profile: 1,000 plan files, 500 trajectories, 300 robot descriptions (about a
# minute; `make test` runs a tenth of it).
fuzz: $(STAMP)
	ROARMCTL_FUZZ=full $(BIN)/python -m pytest -m fuzz tests/test_fuzz.py

bench: $(STAMP)
	for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# Plan the bundled pick-and-place, draw it, and run it on the simulated arm (firmware simulator
# on a pseudo-terminal), then export the plan and the run for Foxglove / ROS 2. Outputs go to out/.
demo: $(STAMP) render
	$(BIN)/roarmctl plan plans/pick_place.yaml -o out/pick_place.traj.json
	$(BIN)/roarmctl visualize-path out/pick_place.traj.json -o out/pick_place.png
	$(BIN)/roarmctl execute out/pick_place.traj.json --sim --yes
	$(BIN)/roarmctl export out/pick_place.traj.json -o out/pick_place.mcap
	$(BIN)/roarmctl export out/pick_place.exec.json -o out/pick_place.exec.mcap
	$(BIN)/roarmctl export out/pick_place.traj.json -o out/pick_place_bag
	$(BIN)/roarmctl export out/pick_place.exec.json -o out/pick_place_exec_bag
	rm -rf out/pick_place_lerobot && $(BIN)/roarmctl datagen plans/datagen/pick_place.yaml -n 4 -o out/pick_place_lerobot --size 320x240 --workers 2

clean:
	rm -rf $(VENV) build *.egg-info src/roarmctl/*.so src/roarmctl/motion/*.so
