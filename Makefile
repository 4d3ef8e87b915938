# dq_fk_ros front door. `make demo` and `make test` work on a fresh machine from nothing.
# Every target is idempotent: with nothing changed, setup does nothing and prints nothing.

PYTHON ?= python3.11
VENV ?= .venv
PY := $(VENV)/bin/python
STAMPS := $(VENV)/.stamps
LOGS := $(VENV)/logs
STEP := scripts/step
PIP := $(PY) -m pip install --disable-pip-version-check

# Every ROS process started from here stays on loopback, on a domain of its own.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
DEMO_DOMAIN_ID ?= $(shell echo $$(( ($$$$ % 80) + 20 )))

BENCH_VENV ?= .venv-bench

# (graphviz: Debian's dot, for dq_fk tf frames and its test)
.PHONY: help setup browser graphviz demo demo-live demo-foxglove test check sanitize bench mutate screenshot clean

help:
	@echo 'make setup  create .venv with ROS 2 Jazzy (PyPI), tf2_msgs and dq_fk_ros'
	@echo 'make demo   setup, then node + fake joint publisher: print every RL15 frame pose'
	@echo 'make demo-live  the same, sweeping the joints, and dq_fk_view: the robot in a browser (Ctrl-C)'
	@echo 'make demo-foxglove  the same with dq_fk_foxglove: the robot in the Foxglove app (Ctrl-C)'
	@echo 'make test   setup (and Chromium for the browser tests), then linters, unit and integration tests'
	@echo 'make check  the edit-test loop: linters and unit tests only (no DDS processes, no browser)'
	@echo 'make sanitize  the C extensions under ASan and UBSan: their tests and a fuzz (FUZZ=long: longer)'
	@echo 'make bench  benchmarks: the core against its peers (installed in .venv-bench)'
	@echo 'make mutate mutation testing of the pure modules (minutes; not part of make test)'
	@echo 'make screenshot  the README picture of dq_fk_view, made by its browser test'
	@echo 'make clean  remove .venv, .venv-bench and build leftovers'

setup: $(STAMPS)/project
	@:

$(STAMPS)/python:
	@$(STEP) "find $(PYTHON) (the ROS 2 Jazzy wheels are built for CPython 3.11)" $(LOGS)/python.log \
	  $(PYTHON) -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version'
	@$(STEP) "create virtual environment $(VENV)" $(LOGS)/venv.log $(PYTHON) -m venv $(VENV)
	@mkdir -p $(STAMPS) && touch $@

$(STAMPS)/runtime: requirements/runtime.txt $(STAMPS)/python
	@echo 'setup: installing ROS 2 Jazzy runtime wheels, numpy, PyYAML'
	@$(STEP) "install requirements/runtime.txt" $(LOGS)/runtime.log $(PIP) -r requirements/runtime.txt
	@touch $@

$(STAMPS)/dev: requirements/dev.txt $(STAMPS)/runtime
	@echo 'setup: installing test and lint tools'
	@$(STEP) "install requirements/dev.txt" $(LOGS)/dev.log $(PIP) -r requirements/dev.txt
	@touch $@

$(STAMPS)/foxglove: requirements/foxglove.txt $(STAMPS)/runtime
	@echo 'setup: installing the Foxglove SDK (the optional extra of dq_fk_foxglove)'
	@$(STEP) "install requirements/foxglove.txt" $(LOGS)/foxglove.log $(PIP) -r requirements/foxglove.txt
	@touch $@

$(STAMPS)/tf2_msgs: vendor/tf2_msgs/CMakeLists.txt vendor/tf2_msgs/package.xml \
                    $(wildcard vendor/tf2_msgs/*/*.msg vendor/tf2_msgs/*/*.srv \
                      vendor/tf2_msgs/*/*.action) requirements/tf2_msgs-build.txt \
                    scripts/tf2_msgs_build.py $(STAMPS)/runtime
	@echo 'setup: providing tf2_msgs (building the vendored copy if missing)'
	@$(STEP) "provide tf2_msgs (scripts/tf2_msgs_build.py)" $(LOGS)/tf2_msgs.log \
	  $(VENV)/bin/python scripts/tf2_msgs_build.py --into $(VENV)
	@touch $@

$(STAMPS)/web: web/package.json web/package-lock.json $(STAMPS)/python
	@echo 'setup: installing the page of dq_fk_view (three.js, urdf-loader: npm ci in web/)'
	@$(STEP) "find npm (Node.js; Debian: apt-get install nodejs npm)" $(LOGS)/npm.log npm --version
	@$(STEP) "npm ci in web/ (web/package-lock.json)" $(LOGS)/web.log \
	  npm ci --prefix web --no-audit --no-fund
	@touch $@

$(STAMPS)/project: setup.py setup.cfg package.xml scripts/rcl_build.py $(wildcard dq_fk_ros/*/_*.c dq_fk_ros/*/*.h) $(STAMPS)/dev \
                  $(STAMPS)/foxglove $(STAMPS)/tf2_msgs $(STAMPS)/web
	@echo 'setup: installing dq_fk_ros (editable)'
	@$(STEP) "install dq_fk_ros in editable mode" $(LOGS)/project.log \
	  $(PIP) --no-deps --no-build-isolation --no-use-pep517 -e .
	@# setup.cfg puts executables where `ros2 run` looks (lib/dq_fk_ros); also put them on
	@# the venv's PATH
	@for exe in $(VENV)/lib/dq_fk_ros/*; do ln -sf ../lib/dq_fk_ros/$${exe##*/} $(VENV)/bin/; done
	@touch $@

demo: setup
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) -m dq_fk_ros.ros.demo

demo-live: setup
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) -m dq_fk_ros.ros.demo --live --view

demo-foxglove: setup
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) -m dq_fk_ros.ros.demo --live --foxglove

test: setup browser graphviz
	@scripts/run_tests $(PY)

# (one pytest-xdist worker a core, up to 4, as scripts/run_tests)
TEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 2); echo $$(( n < 4 ? n : 4 )))
check: setup graphviz
	@start=$$(date +%s); $(PY) -m pytest -q -n $(TEST_WORKERS) test/lint test/unit; rc=$$?; \
	  echo "check: wall time $$(( $$(date +%s) - start )) s"; exit $$rc

# the C extensions built with -fsanitize=address,undefined, their unit tests and the
# hypothesis fuzz of every compiled entry point run under them (scripts/sanitize); FUZZ=ci
# is a short budget (CI), FUZZ=long a deeper search
FUZZ ?= ci
sanitize: setup
	@scripts/sanitize $(PY) $(FUZZ)

# the browser tests need Debian's Chromium and its driver (system packages, like cmake):
# installed with apt when missing and this runs as root, else one line saying how
# $(call apt_need,COMMANDS,PACKAGES,NAME,WHAT FOR): when a command is missing, install the
# Debian packages with apt-get (as root; the log in $(LOGS)/NAME.log), else say the command
define apt_need
	@if ! { $(foreach c,$(1),command -v $(c) >/dev/null &&) true; }; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo 'setup: installing $(2) (apt-get; $(4))'; \
	    mkdir -p $(LOGS); \
	    { apt-get install -y -q $(2) || { apt-get update -q && \
	      apt-get install -y -q $(2); }; } > $(LOGS)/$(3).log 2>&1 || \
	    { echo "setup FAILED: apt-get install $(2) (see $(LOGS)/$(3).log)" >&2; \
	      exit 1; }; \
	  else \
	    echo 'setup FAILED: $(4) need Debian packages $(2); run: sudo apt-get install $(2)' >&2; \
	    exit 1; \
	  fi; \
	fi
endef

browser:
	$(call apt_need,chromium chromedriver,chromium chromium-driver,browser,the browser tests)

graphviz:
	$(call apt_need,dot,graphviz,graphviz,dq_fk tf frames and its test)

$(BENCH_VENV)/.stamp: requirements/bench.txt setup.py
	@echo 'bench: installing benchmark peers into $(BENCH_VENV) (requirements/bench.txt)'
	@$(STEP) "create virtual environment $(BENCH_VENV)" $(BENCH_VENV)-logs/venv.log \
	  $(PYTHON) -m venv $(BENCH_VENV)
	@$(STEP) "install requirements/bench.txt" $(BENCH_VENV)-logs/bench.log \
	  $(BENCH_VENV)/bin/python -m pip install --disable-pip-version-check -r requirements/bench.txt
	@$(STEP) "install dq_fk_ros into $(BENCH_VENV)" $(BENCH_VENV)-logs/project.log \
	  $(BENCH_VENV)/bin/python -m pip install --disable-pip-version-check --no-deps --no-build-isolation --no-use-pep517 -e .
	@touch $@

# bench_calibration.py's peers, each in a venv of its own (pybotics pins numpy < 2)
PEER_VENVS = .venv-figaroh .venv-pybotics
.venv-%/.stamp: requirements/bench-%.txt
	@echo 'bench: installing the calibration peer $* into .venv-$* (requirements/bench-$*.txt)'
	@$(STEP) "create virtual environment .venv-$*" .venv-$*-logs/venv.log $(PYTHON) -m venv .venv-$*
	@$(STEP) "install requirements/bench-$*.txt" .venv-$*-logs/install.log \
	  .venv-$*/bin/python -m pip install --disable-pip-version-check -r requirements/bench-$*.txt
	@touch $@

# every benchmark records its figures (benchmarks/bench_results.py) for docs/performance.md
BENCH_RESULTS = build/bench/results.jsonl
bench: export DQ_FK_BENCH_JSON = $(abspath $(BENCH_RESULTS))
bench: setup $(BENCH_VENV)/.stamp $(addsuffix /.stamp,$(PEER_VENVS))
	@mkdir -p $(dir $(BENCH_RESULTS)) && rm -f $(BENCH_RESULTS)
	@DQ_FK_FIGAROH_PYTHON=$(abspath .venv-figaroh/bin/python) \
	  DQ_FK_PYBOTICS_PYTHON=$(abspath .venv-pybotics/bin/python) \
	  $(PY) benchmarks/bench_calibration.py
	@echo
	@$(BENCH_VENV)/bin/python benchmarks/bench_core.py
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_node.py
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_e2e.py
	@echo
	@for robot in tiago_description/robots/tiago_dual.urdf talos_data/robots/talos_full_v2.urdf \
	  solo_description/robots/solo12.urdf; do \
	  ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_node.py --example-robot-data $$robot \
	    --updates 500 --rounds 3 || exit 1; echo; done
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_e2e.py --example-robot-data \
	  tiago_description/robots/tiago_dual.urdf --rates 1000 --repeat 3 --capacity 0
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_e2e.py --example-robot-data \
	  tiago_description/robots/tiago_dual.urdf --rates 1000 --repeat 3 --capacity 0 \
	  --fastdds-profile config/fastdds_large_tf_localhost.xml
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_rclpy_floor.py
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_view.py
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_foxglove.py
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_flood_memory.py
	@echo
	@$(PY) benchmarks/bench_bag.py
	@$(PY) benchmarks/bench_fleet.py
	@echo
	@ROS_DOMAIN_ID=$(DEMO_DOMAIN_ID) $(PY) benchmarks/bench_tf.py
	@echo
	@$(PY) benchmarks/bench_testing.py
	@$(PY) scripts/performance_doc.py $(BENCH_RESULTS) docs/performance.md

$(STAMPS)/mutation: requirements/mutation.txt $(STAMPS)/dev
	@echo 'setup: installing mutmut (make mutate)'
	@$(STEP) "install requirements/mutation.txt" $(LOGS)/mutation.log $(PIP) -r requirements/mutation.txt
	@touch $@

mutate: setup $(STAMPS)/mutation
	@$(PY) scripts/mutate.py run

# The README's picture of dq_fk_view, taken by its browser test (headless Chromium)
# the README's pictures of dq_fk_view (RL15, UR5, Panda with their meshes), made by the
# browser tests that check them (test/integration/test_view_meshes.py)
screenshot: setup browser
	@DQ_FK_VIEW_SCREENSHOTS=$(CURDIR)/docs $(PY) -m pytest -q -p no:cacheprovider \
	  test/integration/test_view_meshes.py -k 'vendor_robot or helper_frames'
	@echo 'screenshot: docs/dq_fk_view.png, docs/dq_fk_view_ur5.png, docs/dq_fk_view_panda.png'

clean:
	rm -rf $(VENV) $(BENCH_VENV) $(BENCH_VENV)-logs build install log .pytest_cache \
	  web/node_modules
