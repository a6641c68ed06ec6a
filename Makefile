# Two commands on a fresh machine with Python >= 3.11:
#   make demo   set up .venv and run `onboard demo` on the built-in simulated vehicle
#   make test   set up .venv and run the test suite
#   make figures  recompute the README's estimator figures (docs/figures.json, README.md)
# On the vehicle computer (docs/service.md "Install"):
#   sudo make install   venv in $(PREFIX)/venv, config in $(SYSCONFDIR), the systemd unit
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

# make install: DESTDIR stages everything under a directory (packaging); PIP_ARGS adds pip
# arguments (e.g. --no-index --find-links=wheels/ on a boat without internet).
DESTDIR    ?=
PREFIX     ?= /opt/onboard
SYSCONFDIR ?= /etc/onboard
UNITDIR    ?= /etc/systemd/system
CREDSTORE  ?= /etc/credstore
PIP_ARGS   ?=

.PHONY: demo test test-all bench figures setup clean install

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[all]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/onboard demo

test: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

test-all: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/onboard bench

# Recompute every figure of the README's "What it estimates" table into docs/figures.json
# and regenerate the table from it (about 15 min on 2 cores; commit both files).
figures: $(STAMP)
	$(BIN)/onboard validate --write docs/figures.json --readme README.md

clean:
	rm -rf $(VENV) replay-out diagnose-out .pytest_cache

install:
	$(PYTHON) -m onboard.tools.install --destdir "$(DESTDIR)" --prefix "$(PREFIX)" \
	  --sysconfdir "$(SYSCONFDIR)" --unitdir "$(UNITDIR)" --credstore "$(CREDSTORE)" \
	  --pip-args="$(PIP_ARGS)"
