# Two entry points: `make demo` and `make test`. Both create the virtualenv on first use,
# so a fresh machine with only Python 3.11, pip and make is enough.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint wheel-test bench install clean

# Debian and Ubuntu ship venv without ensurepip unless python3-venv is installed: then the
# venv is made without pip and the system's pip installs pip into it.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV) || { echo "make: no ensurepip; a venv without pip, pip from the system's pip"; \
	  rm -rf $(VENV) && $(PYTHON) -m venv --without-pip $(VENV) && \
	  $(PYTHON) -m pip --python $(BIN)/python install --quiet pip; }
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/heliotrack simulate --days 1 --out out/demo

# Two workers (pytest-xdist): CI's two cores.  Each worker is a session of its own (its
# bus-lock folder too); every test's port, pty and folder is its own.  Serial, the suite
# took 557-606 s here; in two workers 310 s, twice with no failure (2026-12-02).  A
# module's tests run on one worker, in order (loadscope): some follow one plant through
# a shutdown and a restart (test_run_plant.py); under `load` a fresh clone's CI split them.
test: $(STAMP) lint wheel-test
	$(BIN)/python -m pytest -q -n 2 --dist loadscope

# Lint, format and types first: they take seconds and fail fast.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

# A plain (not editable) install must run: build the wheel from the tracked files (as from
# a fresh clone; without git, e.g. an unpacked archive, from the tree less what the build
# and the tools write; nothing is written into the tree), install it into a throwaway venv and
# simulate an hour from outside the repository, so only the wheel's files (the packaged
# config/ included) are there to use.  The throwaway venv borrows the installed
# dependencies from $(VENV) through a .pth line (no download); heliotrack itself comes
# from the wheel alone.
wheel-test: $(STAMP)
	@set -e; tmp=$$(mktemp -d); trap 'rm -rf "$$tmp"' EXIT; \
	mkdir "$$tmp/src"; \
	if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then git ls-files -z | tar --null -T - -cf -; \
	else tar --exclude=./$(VENV) --exclude=./out --exclude='*.egg-info' --exclude=__pycache__ \
	  --exclude='.*_cache' --exclude=./build --exclude=./dist -cf - .; fi | tar -xf - -C "$$tmp/src"; \
	$(BIN)/pip wheel --quiet --no-deps --wheel-dir "$$tmp/dist" "$$tmp/src" 2>"$$tmp/build.log" || { cat "$$tmp/build.log"; exit 1; }; \
	$(BIN)/python -m venv --without-pip "$$tmp/venv"; \
	deps=$$($(BIN)/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])'); \
	site=$$("$$tmp/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])'); \
	echo "$$deps" > "$$site/_heliotrack_deps.pth"; \
	$(BIN)/pip --python "$$tmp/venv/bin/python" install --quiet --no-deps "$$tmp"/dist/heliotrack-*.whl; \
	cd "$$tmp" && venv/bin/heliotrack simulate --hours 1 --out out --no-report > run.log; \
	venv/bin/python -c 'import heliotrack, sys; sys.exit("heliotrack imported from " + heliotrack.__file__ if "/venv/" not in heliotrack.__file__ else 0)'; \
	tail -1 run.log; echo "wheel-test: a plain install of the wheel simulates an hour"

bench: $(STAMP)
	$(BIN)/heliotrack bench all

clean:
	rm -rf $(VENV) out .pytest_cache
