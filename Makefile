# Two commands on a fresh machine (only Python 3.11, pip and make needed):
#   make run    set everything up and run the main job
#   make test   set everything up and run the whole test suite (what .ci/run does; it includes
#               test/test_docs_figures.py: python -m tools.docs_figures --check)
#   make docs   rewrite the generated blocks of README.md and docs/*.md from their commands
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: setup run test lint bench docs clean

$(STAMP): requirements.txt requirements-dev.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r requirements-dev.txt
	$(BIN)/python -m pip install -q --no-deps -e .
	touch $(STAMP)

setup: $(STAMP)

run: setup
	bash bags/twin_main_job.sh

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/lint-imports

test: setup lint
	$(BIN)/python -c "import rclpy, std_msgs.msg, sensor_msgs.msg, geometry_msgs.msg, diagnostic_msgs.msg"
	$(BIN)/python -m pytest -q

bench: setup
	$(BIN)/python -m benchmarks.run --write-docs

docs: setup
	$(BIN)/python -m tools.docs_figures

clean:
	rm -rf $(VENV) build install log .pytest_cache .ruff_cache .import_linter_cache
