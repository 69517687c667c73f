# Two commands for a fresh machine: `make run` and `make test`. Both create .venv on first use.
# `make run` installs what running needs (the package with numpy, scipy, sympy, numba, mcap,
# rosbags, matplotlib, PyYAML, xacro, and rclpy with the message packages from PyPI); `make test`
# adds the test, lint and type-check tools (requirements-dev.txt) and the `studies` extra.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
RUN_STAMP  := $(VENV)/.installed-run
TEST_STAMP := $(VENV)/.installed-test

# DDS stays on this machine unless the caller chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: run test bench clean

$(RUN_STAMP): setup.py requirements-ros.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-ros.txt -e .
	touch $(RUN_STAMP)

$(TEST_STAMP): $(RUN_STAMP) setup.py requirements-dev.txt
	$(PY) -m pip install --quiet -r requirements-dev.txt -e '.[studies]'
	touch $(TEST_STAMP)

run: $(RUN_STAMP)
	$(VENV)/bin/impact-arm run

test: $(TEST_STAMP)
	$(PY) -m pytest -q test

clean:
	rm -rf $(VENV) build install log *.egg-info
