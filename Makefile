# Two entry points for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
PIP := $(BIN)/pip install -q -c constraints.txt
RUNTIME := $(VENV)/.runtime
DEV := $(VENV)/.dev

.PHONY: demo test docs setup bench clean

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip

# the runtime dependencies only: what a user of `lfstream stream` needs
$(RUNTIME): pyproject.toml constraints.txt | $(VENV)/bin/python
	$(PIP) -e .
	touch $(RUNTIME)

# the test, docs and Ray extras on top
$(DEV): $(RUNTIME)
	$(PIP) -e '.[dev,docs,ray]'
	touch $(DEV)

setup: $(DEV)

demo: $(RUNTIME)
	$(BIN)/lfstream stream

test: $(DEV)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest tests
	$(MAKE) docs

docs: $(DEV)
	$(BIN)/python bench/plots.py >/dev/null
	$(BIN)/sphinx-build -W --keep-going -q -b html docs docs/_build/html

bench: $(DEV)
	$(BIN)/python bench/refocus.py

clean:
	rm -rf $(VENV) build *.egg-info docs/_build
