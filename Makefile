# Two entry points for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test setup bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[dev,ray]'
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/lfstream stream

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest tests

bench: $(STAMP)
	$(BIN)/python bench/refocus.py

clean:
	rm -rf $(VENV) build *.egg-info
