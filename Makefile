# Two commands do everything on a fresh machine (see README.md):
#   make demo   venv from the pins, install, run the closed-loop CBHA scene in simulation
#   make test   venv from the pins, install, run the whole test suite
# The venv is rebuilt only when a pin file changes (stamp files), so warm runs start at once.
# Installing also compiles the numba kernels once into their on-disk cache (cbha_inverse.warmup;
# again whenever a kernel module changes), so nothing timed later pays for the compile.

# ROS 2 Jazzy wheels on PyPI are built for CPython 3.11.
PYTHON ?= $(shell command -v python3.11 2>/dev/null)
VENV ?= .venv
VPY := $(VENV)/bin/python
PINS_STAMP := $(VENV)/.pins-stamp
INSTALL_STAMP := $(VENV)/.install-stamp
KERNELS_STAMP := $(VENV)/.kernels-stamp
EXPORTS_STAMP := $(VENV)/.rosidl-exports-stamp
INTERFACES_STAMP := $(VENV)/.interfaces-stamp
INTERFACE_FILES := $(shell find cbha_inverse/interfaces -type f -not -name '*.pyc')
KERNEL_SOURCES := $(wildcard cbha_inverse/core/_kernels/*.py)
KERNEL_TESTS ?= test/core/test_core_kernels_qp.py test/core/test_core_kernels_rows_qp.py \
  test/core/test_core_obstacle_rows.py test/core/test_core_kernels.py \
  test/core/test_core_linalg_btd.py test/core/test_core_tick.py test/core/test_core_links.py \
  test/core/test_core_so3.py test/core/test_core_actuation.py test/core/test_core_sensors.py \
  test/core/test_core_statics.py test/core/test_solver_paths.py test/core/test_core_records.py \
  test/estimate/test_estimate_filter.py test/estimate/test_estimate_shape.py \
  test/core/test_core_effector_orientation.py test/core/test_core_kernels_obstacles.py \
  test/report/test_report_tick_flops.py::test_the_multiply_add_chains_follow_their_closed_form
# with the JIT off: the tests of numba's compiled signatures and allocations have nothing to
# check, and the long estimation runs and the random poses repeat what the short ones cover
KERNEL_DESELECT ?= test/core/test_core_linalg_btd.py::test_compiled_accepts_strided_and_read_only_blocks \
  test/core/test_core_tick.py::test_a_thousand_ticks_allocate_nothing_but_their_results \
  test/estimate/test_estimate_shape.py::test_a_softer_plant_is_a_weight_error_not_a_tip_bias \
  test/estimate/test_estimate_shape.py::test_the_weight_error_and_a_tip_payload_are_two_unknowns \
  test/estimate/test_estimate_filter.py::test_the_filter_averages_the_pot_noise_at_a_held_pose \
  test/core/test_core_effector_orientation.py::test_random_reachable_poses_are_reached_open_loop
COVERAGE_ARGS ?= --cov=cbha_inverse
# the timing phase measures its pytest process only (test/coverage_timing.cfg: no subprocess patch)
TIMING_COVERAGE_ARGS ?= $(COVERAGE_ARGS) --cov-config=test/coverage_timing.cfg
COVERAGE_REPORT ?= --cov-report=term:skip-covered
comma := ,
space := $(subst ,, )
DEMO_OUT ?= output/demo
PYTEST_ARGS ?=
# make test runs the suite in two phases (docs/design.md "Tests"): every test but the timing ones
# on TEST_WORKERS pytest-xdist workers (each reserving its own ROS_DOMAIN_ID, test/conftest.py),
# then the timing tests (`-m timing`: closed loops, lag, stop deadlines, replays, hosts) in one
# process with the cores to themselves; coverage appends the second phase to the first (its node
# processes untraced: test/coverage_timing.cfg). Two workers: three were no faster on 2 cores
# (docs/lab-notes.md).
TEST_WORKERS ?= 2
# small dense solves are far slower with OpenBLAS worker threads on 2 loaded cores
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1

.PHONY: demo test help venv install lint bench report constraints clean cover-kernels mutate

demo: install  ## the closed-loop CBHA scene in simulation: tracking error and timing (~2 min)
	$(VPY) -m cbha_inverse.experiments.demo --output $(DEMO_OUT)

# Coverage over both phases (the first phase's child processes included: coverage's patch =
# subprocess, setup.cfg; the timing phase's pytest process only, test/coverage_timing.cfg), then
# the total of the non-compiled code (the numba kernels run as machine code, not Python: make
# cover-kernels measures them with the JIT off). Both phases run even when the first
# fails; each prints its 15 slowest tests; CBHA_TEST_SHARED holds what both phases and later runs
# reuse.
test: install  ## the whole test suite with coverage (~8 min on 2 cores)
	@shared=$(abspath $(VENV))/test-shared; mkdir -p $$shared; export CBHA_TEST_SHARED=$$shared; \
	listed=$$shared/timing-files; rm -f $$listed; \
	start=$$(date +%s); \
	CBHA_TIMING_FILES_OUT=$$listed $(VPY) -m pytest test -q -rs -m 'not timing' \
	  -n $(TEST_WORKERS) --dist worksteal --durations=15 $(COVERAGE_ARGS) --cov-report= \
	  $(PYTEST_ARGS); first=$$?; \
	middle=$$(date +%s); \
	files=$$(tail -n +2 $$listed 2>/dev/null); \
	if [ -n "$$files" ]; then check=CBHA_TIMING_FILES_IN=$$listed; else files=test; check=; \
	  echo "make test: no list of the timing tests' files ($$listed), collecting test/"; fi; \
	env $$check $(VPY) -m pytest $$files -q -rs -m timing --durations=15 $(TIMING_COVERAGE_ARGS) \
	  --cov-append $(COVERAGE_REPORT) $(PYTEST_ARGS); second=$$?; \
	end=$$(date +%s); \
	echo "make test: $$((middle - start)) s on $(TEST_WORKERS) workers, $$((end - middle)) s of timing tests"; \
	for status in $$first $$second; do [ $$status -eq 0 ] || [ $$status -eq 5 ] || exit $$status; done
	@$(VPY) -m coverage report --omit='$(subst $(space),$(comma),$(KERNEL_SOURCES))' \
	  | tail -n 1 | sed 's/^TOTAL/non-compiled code (kernels omitted): TOTAL/'

# The kernel tests with NUMBA_DISABLE_JIT=1: the compiled code runs as Python and is measured.
# A record's boxing is code generation, run only while numba compiles: its tests run again
# with the JIT on and append to the same coverage.
cover-kernels: install  ## coverage of the numba kernels, their tests with the JIT off
	NUMBA_DISABLE_JIT=1 $(VPY) -m pytest $(KERNEL_TESTS) -q -n $(TEST_WORKERS) --cov=cbha_inverse \
	  --cov-report= $(addprefix --deselect ,$(KERNEL_DESELECT)) $(PYTEST_ARGS)
	$(VPY) -m pytest test/core/test_core_records.py -q --cov=cbha_inverse --cov-append \
	  --cov-report= $(PYTEST_ARGS)
	$(VPY) -m coverage report --include='$(subst $(space),$(comma),$(KERNEL_SOURCES))'

# Mutation testing (not in CI: ~20-30 min on 2 cores) of the modules a wrong line hurts most;
# the modules and their tests are the [mutmut] section of setup.cfg. Survivors: mutmut results.
mutate: install  ## mutation testing of the safety-critical modules (~20-30 min, not in CI)
	rm -rf mutants
	nice -n 10 $(VPY) -m mutmut run --max-children 2 || true
	$(VPY) -m mutmut results

# `make help`: the targets, one line each (the `## ` comment after a target's name).
help:  ## list the targets
	@awk 'BEGIN {FS = ":.*## "} /^[a-z-]+:.*## / {printf "  make %-14s %s\n", $$1, $$2}' $(MAKEFILE_LIST)

venv: $(PINS_STAMP)  ## the virtual environment .venv from the pins

install: $(INSTALL_STAMP) $(KERNELS_STAMP) $(INTERFACES_STAMP)  ## venv + editable install + compiled kernels + messages

$(PINS_STAMP): requirements.txt requirements-dev.txt constraints.txt
	@if [ -z "$(PYTHON)" ]; then \
	  echo 'error: python3.11 not found (ROS 2 Jazzy wheels need CPython 3.11); set PYTHON=/path/to/python3.11' >&2; \
	  exit 1; fi
	@test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt -c constraints.txt
	@touch $@

$(INSTALL_STAMP): $(PINS_STAMP) setup.py setup.cfg package.xml
	$(VPY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $@

# numba's cache is keyed by each function's own source file: an entry that calls a changed
# kernel of another file would load its stale machine code, so a kernel change drops the cache
$(KERNELS_STAMP): $(INSTALL_STAMP) $(KERNEL_SOURCES)
	rm -f cbha_inverse/core/_kernels/__pycache__/*.nbi cbha_inverse/core/_kernels/__pycache__/*.nbc
	$(VPY) -m cbha_inverse.warmup
	@touch $@

# The ROS interface wheels' CMake export files name the wheel builder's Python/numpy include
# folders; rewrite them to this venv's (idempotent, touches only $(VENV)/share) so that colcon can
# build an interface package such as robotino_msgs (cbha_build_robotino_msgs, the bridge tests).
$(EXPORTS_STAMP): $(PINS_STAMP)
	$(VPY) -m cbha_inverse.interfaces.rosidl_exports $(VENV)
	@touch $@

# The message packages the nodes use that PyPI lacks (tf2_msgs, robotino_msgs, control_msgs;
# cbha_inverse/interfaces/) are built with colcon (CMake and a C/C++ compiler from the system)
# and installed into the venv beside the wheels' messages, where every process of the venv finds
# them without sourcing anything (cbha_inverse.interfaces.venv_install); again whenever their
# files or the pins change.
$(INTERFACES_STAMP): $(EXPORTS_STAMP) $(INSTALL_STAMP) $(INTERFACE_FILES)
	$(VPY) -m cbha_inverse.interfaces.venv_install
	@touch $@

lint: install  ## ament_flake8, ament_pep257 and the layout checks (test/lint)
	$(VPY) -m pytest test/lint -q

bench: install  ## BTD and inverse-tick benchmarks
	$(VPY) -m cbha_inverse.report.cli bench

report: install  ## every report (benchmarks, stability, accuracy, FEM) into output/
	$(VPY) -m cbha_inverse.report.cli all

# Replay regression goldens (test/replay.py): replays test/data/replay/* and rewrites goldens.npz.
.PHONY: goldens
goldens: install  ## regenerate the replay regression goldens
	$(VPY) test/regen_goldens.py

# Re-pin the transitive dependencies after changing requirements*.txt.
constraints: $(PINS_STAMP)  ## re-pin the transitive dependencies
	( echo '# Transitive pins: pip freeze of a venv made from requirements-dev.txt. Regenerate: make constraints'; \
	  $(VPY) -m pip freeze --disable-pip-version-check | grep -vE '^(-e|cbha|# Editable)' ) > constraints.txt

clean:  ## remove the venv and every build and output folder
	rm -rf $(VENV) build install log output .pytest_cache *.egg-info mutants .coverage*
