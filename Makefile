# One-command set-up: `make demo` and `make test` create .venv/ with pinned dependencies.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# tf2_msgs/msg/TFMessage (/tf, /tf_static) is not among the PyPI wheels: where no ROS install
# provides it, resource/tf2_msgs is built with the rosidl generators and installed into .venv.
TF2_MSGS  := resource/tf2_msgs
TF2_STAMP := $(VENV)/.tf2_msgs
TF2_BUILD := $(VENV)/build/tf2_msgs
# Python 3.12 (Jazzy's own) where one runs, else python3 >= 3.10. Each candidate is tried,
# because a pyenv shim can exist on PATH without a working interpreter behind it.
BASE_PYTHON ?= $(shell for p in python3.12 $$HOME/.pyenv/versions/3.12*/bin/python3.12 python3; do \
	$$p -c 'import sys; sys.exit(sys.version_info < (3, 10))' >/dev/null 2>&1 && { command -v $$p; break; }; done)

.PHONY: demo test lint typecheck unit bench clean venv

venv: $(STAMP) $(TF2_STAMP)

$(STAMP): requirements.txt setup.py setup.cfg
	@test -n "$(BASE_PYTHON)" || { echo "no Python >= 3.10 found: install Python 3.12" >&2; exit 1; }
	test -x $(PY) || $(BASE_PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	touch $(STAMP)

# Built into the venv's own prefix (its lib/ is on the library path the ROS wheels set up), so
# `import tf2_msgs` needs no environment variable. A tf2_msgs from outside the venv (a sourced
# ROS install) is used as it is. The wheels' CMake files name include directories that do not
# exist here: resource/tf2_msgs/CMakeLists.txt drops them.
$(TF2_STAMP): $(STAMP) $(wildcard $(TF2_MSGS)/* $(TF2_MSGS)/msg/*)
	@if $(PY) -c 'import sys, tf2_msgs; sys.exit(tf2_msgs.__file__.startswith(sys.prefix))' 2>/dev/null; then \
		echo "tf2_msgs comes from the ROS install: not built"; \
	else \
		command -v cmake >/dev/null && command -v cc >/dev/null && command -v c++ >/dev/null || { \
			echo "building tf2_msgs needs cmake and a C/C++ compiler (apt-get install cmake g++)" >&2; exit 1; }; \
		echo "building tf2_msgs into $(VENV)"; mkdir -p $(TF2_BUILD); \
		export AMENT_PREFIX_PATH="$(abspath $(VENV))" PATH="$(abspath $(VENV))/bin:$$PATH"; \
		cmake -S $(TF2_MSGS) -B $(TF2_BUILD) -Wno-dev -DCMAKE_BUILD_TYPE=Release \
			-DCMAKE_INSTALL_PREFIX="$(abspath $(VENV))" -DCMAKE_PREFIX_PATH="$(abspath $(VENV))" \
			-DPython3_EXECUTABLE="$(abspath $(PY))" -DBUILD_TESTING=OFF >$(TF2_BUILD).log 2>&1 \
		&& cmake --build $(TF2_BUILD) -j 2 >>$(TF2_BUILD).log 2>&1 \
		&& cmake --install $(TF2_BUILD) >>$(TF2_BUILD).log 2>&1 \
		&& $(PY) -c 'from tf2_msgs.msg import TFMessage' \
		|| { tail -n 30 $(TF2_BUILD).log >&2; echo "building tf2_msgs failed: $(TF2_BUILD).log" >&2; exit 1; }; \
	fi
	touch $@

demo: venv
	$(VENV)/bin/linelaser-calib demo bags

lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

typecheck: venv
	$(VENV)/bin/mypy linelaser_calib msg_adapters

# Two workers (pytest-xdist): the suite is mostly one process's work, and this machine has
# two cores; the ROS tests of the two workers use disjoint DDS domains (test/ros_helpers.py).
# The timed live replays (marked serial) then run alone: at 10x they need a free core.
# One BLAS thread per test process, as the console scripts and the nodes run
# (linelaser_calib/entry.py): the tests start nodes in their own process, and a second
# OpenBLAS thread waiting for a core beside the other worker slowed one live solve 25x.
unit: venv
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n 2 -m "not serial"
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -m serial

test: lint typecheck unit

clean:
	rm -rf $(VENV) build install log *.egg-info
