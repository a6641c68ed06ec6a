# Two commands on a fresh machine with Python >= 3.11:
#   make demo   set up .venv and run `onboard demo` on the built-in simulated vehicle
#   make test   set up .venv and run the test suite
#   make figures  recompute every figure (docs/figures.json) and regenerate the README's
#                 table, the docs pages' results tables and docs/results.csv from it
#   make docs     regenerate the README's and the docs pages' tables from docs/figures.json
#                 and docs/tuning.json (nothing recomputed: seconds)
# On the vehicle computer (docs/service.md "Install"):
#   sudo make install   venv in $(PREFIX)/venv, config in $(SYSCONFDIR), the systemd unit
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

# make install: the wheel of this tree, built by the installed venv's pip (or WHEEL, one
# built elsewhere), installed into $(PREFIX)/venv. DESTDIR stages everything under a
# directory (packaging); PIP_ARGS adds pip arguments to the build and the install (e.g.
# --no-index --find-links=wheels/ on a boat without internet: wheels/ then holds the
# dependencies' wheels and setuptools, or give WHEEL).
DESTDIR    ?=
PREFIX     ?= /opt/onboard
SYSCONFDIR ?= /etc/onboard
UNITDIR    ?= /etc/systemd/system
CREDSTORE  ?= /etc/credstore
PIP_ARGS   ?=
WHEEL      ?=

.PHONY: demo test test-all bench compiled bench-compiled figures docs setup clean install

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[all]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/onboard demo

# On every core (pytest-xdist). --dist loadscope, scoped by tests/conftest.py: each module
# runs whole on one worker (a module's shared fixture, one simulated flight for several
# tests, is computed once), the modules sharing the figures' memoised runs together.
# PYTEST_PARALLEL= runs the suite in one process.
PYTEST_PARALLEL ?= -n auto --dist loadscope

test: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow" --durations=25 $(PYTEST_PARALLEL)

test-all: $(STAMP)
	$(BIN)/python -m pytest -q $(PYTEST_PARALLEL)

bench: $(STAMP)
	$(BIN)/onboard bench

# The compiled build (setup.py; docs/performance.md "The compiled build"): the wheel with
# the replay's hot path compiled by mypyc into dist/, then `onboard bench` run on it from
# build/compiled (the venv's dependencies, the checkout's code nowhere on the path).
# On the vehicle: sudo make install WHEEL=dist/onboard-0.1.0-cp311-cp311-linux_x86_64.whl
compiled: $(STAMP)
	rm -rf build dist/onboard-*-cp*.whl
	ONBOARD_COMPILE=1 $(BIN)/python -m pip wheel --quiet --no-build-isolation --no-deps \
	  --wheel-dir dist .
	$(BIN)/python -m pip install --quiet --no-deps --target build/compiled dist/onboard-*-cp*.whl

bench-compiled: compiled
	cd build && PYTHONPATH=$(CURDIR)/build/compiled $(CURDIR)/$(BIN)/python -m onboard bench

# Recompute every figure into docs/figures.json and regenerate the README's "What it
# estimates" table and the docs pages' generated tables from it (docs/reproducing.md;
# of the order of 40 min on 2 cores; commit docs/figures.json, README.md and docs/). One estimator
# only: $(BIN)/python -m validation figures --only 'aie.*' --write docs/figures.json --readme README.md --docs docs
figures: $(STAMP)
	$(BIN)/python -m validation figures --write docs/figures.json --readme README.md --docs docs \
	  --results docs/results.csv

# Regenerate the README's and the docs pages' tables from docs/figures.json and
# docs/tuning.json through their templates (validation/templates/), nothing recomputed.
docs: $(STAMP)
	$(BIN)/python -m validation figures --readme README.md --docs docs --results docs/results.csv
	$(BIN)/python -m validation tune --page docs/aie.md

clean:
	rm -rf $(VENV) replay-out diagnose-out .pytest_cache build dist

install:
	$(PYTHON) -m onboard.apps.install --destdir "$(DESTDIR)" --prefix "$(PREFIX)" \
	  --sysconfdir "$(SYSCONFDIR)" --unitdir "$(UNITDIR)" --credstore "$(CREDSTORE)" \
	  --pip-args="$(PIP_ARGS)" --wheel="$(WHEEL)"
