# Two commands set everything up on a fresh machine with Python 3.11:
#   make demo   - create .venv if missing, install gridshell, run the default job (2.4 m mock-up)
#   make test   - same set-up, then run the test suite
PYTHON ?= python3.11
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=
# the cases run in one process per core (pytest-xdist); PYTEST_ARGS="-n 0" runs them in this one
PARALLEL ?= -n logical --durations=20

.PHONY: demo test test-fast bench clean setup

setup: $(STAMP)

$(BIN)/python:
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "Python 3.11 is required: install python3.11 (or run make PYTHON=/path/to/python3.11)"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[test]"
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gridshell run

test: $(STAMP)
	$(BIN)/python -m pytest $(PARALLEL) $(PYTEST_ARGS)

test-fast: $(STAMP)
	$(BIN)/python -m pytest -m "not slow" $(PARALLEL) $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,bench]"
	@for f in benchmarks/*.py; do case "$$f" in benchmarks/any_roof.py|benchmarks/statics_aware.py) continue;; esac; \
		echo "== $$f"; $(BIN)/python $$f || exit 1; done
	@echo "== benchmarks/any_roof.py (a sample; every size: $(BIN)/python benchmarks/any_roof.py)"
	$(BIN)/python benchmarks/any_roof.py --cells 60 --surfaces 5
	@echo "== benchmarks/statics_aware.py (a sample; every roof and size: $(BIN)/python benchmarks/statics_aware.py)"
	$(BIN)/python benchmarks/statics_aware.py --cells 60 --surfaces 2 --match mockup,Hall,gen

clean:
	rm -rf out build *.egg-info .pytest_cache
