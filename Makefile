# One-command set-up: `make demo` and `make test` create .venv/ with pinned dependencies.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# Python 3.12 (Jazzy's own) where one runs, else python3 >= 3.10. Each candidate is tried,
# because a pyenv shim can exist on PATH without a working interpreter behind it.
BASE_PYTHON ?= $(shell for p in python3.12 $$HOME/.pyenv/versions/3.12*/bin/python3.12 python3; do \
	$$p -c 'import sys; sys.exit(sys.version_info < (3, 10))' >/dev/null 2>&1 && { command -v $$p; break; }; done)

.PHONY: demo test lint typecheck unit bench clean venv

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg
	@test -n "$(BASE_PYTHON)" || { echo "no Python >= 3.10 found: install Python 3.12" >&2; exit 1; }
	test -x $(PY) || $(BASE_PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/linelaser-calib demo bags

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

typecheck: $(STAMP)
	$(VENV)/bin/mypy linelaser_calib msg_adapters

# Two workers (pytest-xdist): the suite is mostly one process's work, and this machine has
# two cores; the ROS tests of the two workers use disjoint DDS domains (test/ros_helpers.py).
# The timed live replays (marked serial) then run alone: at 10x they need a free core.
unit: $(STAMP)
	$(PY) -m pytest -q -n 2 -m "not serial"
	$(PY) -m pytest -q -m serial

test: lint typecheck unit

clean:
	rm -rf $(VENV) build install log *.egg-info
