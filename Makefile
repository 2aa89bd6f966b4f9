# Two commands on a fresh machine (Python 3.11, pip, make, cmake, gcc and g++ needed):
#   make run    set everything up and run the main job
#   make test   set everything up and run the whole test suite (what .ci/run does)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TF2    := $(VENV)/.tf2_msgs
VENV_ABS = $(abspath $(VENV))
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: setup tf2-msgs run test lint bench clean

$(STAMP): requirements.txt requirements-dev.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r requirements-dev.txt
	$(BIN)/python -m pip install -q --no-deps -e .
	touch $(STAMP)

# tf2_msgs (TFMessage only) built from interfaces/ with the venv's rosidl generators and installed
# into the venv, so replay publishes /tf and /tf_static as tf2_msgs/msg/TFMessage (not on PyPI).
# About 10 s (configure 1 s, compile 6.5 s on 2 cores) plus the build-only wheels.
$(TF2): $(STAMP) interfaces/requirements.txt $(wildcard interfaces/tf2_msgs/* interfaces/tf2_msgs/msg/*)
	$(BIN)/python -m pip install -q -r interfaces/requirements.txt
	rm -rf build/tf2_msgs
	cmake -S interfaces/tf2_msgs -B build/tf2_msgs --log-level=WARNING -DBUILD_TESTING=OFF \
	  -DCMAKE_INSTALL_PREFIX=$(VENV_ABS) -DCMAKE_PREFIX_PATH=$(VENV_ABS) \
	  -DPython3_EXECUTABLE=$(VENV_ABS)/bin/python
	cmake --build build/tf2_msgs -j2 -- --no-print-directory > build/tf2_msgs.log || (cat build/tf2_msgs.log; false)
	cmake --install build/tf2_msgs > /dev/null
	$(BIN)/python -c "import tf2_msgs.msg"
	touch $@

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

clean:
	rm -rf $(VENV) build install log .pytest_cache .ruff_cache .import_linter_cache
