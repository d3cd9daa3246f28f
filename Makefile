# One-command set-up: `make demo` and `make test` create .venv/ with pinned dependencies.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# Python 3.12 (Jazzy's own) where it can be found, else python3 >= 3.10.
BASE_PYTHON ?= $(shell command -v python3.12 2>/dev/null || ls -d $$HOME/.pyenv/versions/3.12*/bin/python3.12 2>/dev/null | tail -n 1 || command -v python3)

.PHONY: demo test lint typecheck unit bench clean venv

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg
	@test -n "$(BASE_PYTHON)" || { echo "no python3 found: install Python 3.12 or >= 3.10" >&2; exit 1; }
	@$(BASE_PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 10))' || { echo "$(BASE_PYTHON) is older than 3.10" >&2; exit 1; }
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

unit: $(STAMP)
	$(PY) -m pytest -q

test: lint typecheck unit

clean:
	rm -rf $(VENV) build install log *.egg-info
