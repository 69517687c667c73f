# Two commands for a fresh machine: `make run` and `make test`. Both create .venv on first use
# and install everything, including rclpy and the message packages from PyPI.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

# DDS stays on this machine unless the caller chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: run test bench clean

$(STAMP): setup.py requirements-ros.txt requirements-dev.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-ros.txt -r requirements-dev.txt
	$(PY) -m pip install --quiet -e .
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/impact-arm run

test: $(STAMP)
	$(PY) -m pytest -q test

clean:
	rm -rf $(VENV) build install log *.egg-info
