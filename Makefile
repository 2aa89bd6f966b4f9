# Two commands on a fresh machine (Python 3.11, pip, make, cmake, gcc and g++ needed):
#   make run    set everything up and run the main job
#   make test   set everything up and run the whole test suite (what .ci/run does; it includes
#               test/test_docs_figures.py: python -m tools.docs_figures --check)
#   make docs   rewrite the generated blocks of README.md and docs/*.md from their commands
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TF2    := $(VENV)/.tf2_msgs
VENV_ABS = $(abspath $(VENV))
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: setup tf2-msgs run test lint bench docs clean

$(STAMP): requirements.txt requirements-dev.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r requirements-dev.txt
	$(BIN)/python -m pip install -q --no-deps -e .
	touch $(STAMP)

# tf2_msgs (TFMessage only) built from interfaces/ with the venv's rosidl generators and installed
# into the venv, so replay publishes /tf and /tf_static as tf2_msgs/msg/TFMessage (not on PyPI).
# About 7 s on 2 cores (a fresh `make setup`: 68 s with it, 51 s without). If it cannot be built
# (no cmake or compiler), set-up goes on with a warning and replay skips those two topics, saying
# why; in CI (CI set) that is an error.
$(TF2): $(STAMP) interfaces/requirements.txt interfaces/build_tf2_msgs.sh $(wildcard interfaces/tf2_msgs/* interfaces/tf2_msgs/msg/*)
	@if bash interfaces/build_tf2_msgs.sh $(VENV) build/tf2_msgs; then touch $@; \
	elif [ -n "$$CI" ]; then exit 1; \
	else echo "warning: tf2_msgs not built (above): replay will skip /tf and /tf_static" >&2; fi

tf2-msgs: $(TF2)

setup: $(STAMP) $(TF2)

run: setup
	bash bags/twin_main_job.sh

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/lint-imports

test: setup lint
	$(BIN)/python -c "import rclpy, std_msgs.msg, sensor_msgs.msg, geometry_msgs.msg, diagnostic_msgs.msg, tf2_msgs.msg"
	$(BIN)/python -m pytest -q

bench: setup
	$(BIN)/python -m benchmarks.run --write-docs

docs: setup
	$(BIN)/python -m tools.docs_figures

clean:
	rm -rf $(VENV) build install log .pytest_cache .ruff_cache .import_linter_cache
