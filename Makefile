# Two commands do all the set-up on a fresh machine (Python 3.11+ with venv):
#   make run    - the main job: a 4096-seed sweep on the fastest faithful backend here (installs only what it
#                 needs: the package, and warp-lang where a GPU is; not the training and test stack)
#   make test   - everything CI checks: the test suite, the docs site built strict, and LeRobot's own tools
#                 on the plugin (tests/lerobot/, in a Python 3.12 venv of its own: lerobot 0.6.1's pins)
# Parts: make pytest (the suite alone), make docs, make test-lerobot; make quick: the suite without its slow tests.
# Both install the tested set, requirements/lock.txt (pyproject.toml declares the ranges a user's own environment
# may hold; the lock is the one point in them CI proves). make test-newest: the newest versions the ranges allow,
# by hand (docs/install.md has its last result).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
LOCK := requirements/lock.txt
# what `make run` needs: the base, and warp-lang (388 MB) only where a GPU is, which `auto` then runs MJX-Warp on
# (without one it picks MuJoCo C). `make test` after it installs the rest; the full install stamps this too, so
# `make run` after `make test` installs nothing. Fresh clone, this 2-core machine: 1.5 min and 1.5 GB against the
# full set's 2.3 min and 3.4 GB (docs/getting-started.md)
RUN_STAMP := $(VENV)/.installed-run
RUN_EXTRAS := $(shell nvidia-smi -L >/dev/null 2>&1 && echo '[warp]')
export MJX_PUSHT_JAX_CACHE ?= $(CURDIR)/.jax_cache

# lerobot 0.6.1 needs Python >= 3.12, torch < 2.12 and numpy < 2.3: its tests get a venv of their own
PYTHON312 ?= $(shell for p in python3.12 $$(ls -d $$HOME/.pyenv/versions/3.12*/bin/python3.12 2>/dev/null); do \
	$$p -V >/dev/null 2>&1 && { echo $$p; break; }; done)
LEROBOT_VENV := .venv-lerobot
# the stamp is renamed when the install line changes, so that an older venv is brought up to it
LEROBOT_STAMP := $(LEROBOT_VENV)/.installed-diffusion

.PHONY: run test pytest quick python312 test-lerobot test-newest docs scene bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

$(RUN_STAMP): pyproject.toml $(LOCK) | $(BIN)/python
	$(BIN)/python -m pip install -q -c $(LOCK) -e '.$(RUN_EXTRAS)'
	touch $(RUN_STAMP)

$(STAMP): pyproject.toml $(LOCK) | $(BIN)/python
	$(BIN)/python -m pip install -q -c $(LOCK) -e '.[warp,gym,video,train,test]'
	touch $(STAMP) $(RUN_STAMP)

run: $(RUN_STAMP)
	$(BIN)/mjx-pusht sweep

scene: $(RUN_STAMP)
	$(BIN)/mjx-pusht scene

# The LeRobot venv (2.3 min to install on this 2-core machine, mostly downloads) is made while the suite runs; its
# tests run after the suite, on two workers. Run beside the suite's three workers, they took longer (339 s against
# 221 s) and so did the suite: a fresh clone's `make test` took 1,824 s so, against the
# suite's 1,128 s alone (notebook lead22). A failure in any part fails `make test`, each part's output shown.
test: $(STAMP) $(VENV)/.docs-installed
	@( $(MAKE) --no-print-directory $(LEROBOT_STAMP) > $(VENV)/lerobot-install.log 2>&1 || exit 3 ) & lerobot=$$!; \
	$(BIN)/python -m pytest -q; rc=$$?; \
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict || rc=1; \
	wait $$lerobot; lrc=$$?; \
	if [ $$lrc = 3 ]; then cat $(VENV)/lerobot-install.log; echo "make test: the LeRobot venv's install failed"; exit 1; fi; \
	echo "== tests/lerobot (LeRobot's venv)"; \
	$(LEROBOT_VENV)/bin/python -m pytest -q -n 2 tests/lerobot; lrc=$$?; \
	test $$rc = 0 && test $$lrc = 0

pytest: $(STAMP)
	$(BIN)/python -m pytest -q

# the quick loop while developing: the suite without the tests that compile MJX or run MJX-Warp (the test stack
# is installed first: `make run` alone installs none of it)
quick: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

$(VENV)/.docs-installed: $(STAMP)
	$(BIN)/python -m pip install -q -c $(LOCK) -e '.[docs]'
	touch $@

docs: $(VENV)/.docs-installed
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

$(LEROBOT_STAMP): pyproject.toml plugins/lerobot_env_mjx_pusht/pyproject.toml
	@test -n "$(PYTHON312)" || { echo "make test-lerobot needs Python 3.12 (lerobot 0.6.1 requires it): set PYTHON312=/path/to/python3.12"; exit 2; }
	$(PYTHON312) -m venv $(LEROBOT_VENV)
	$(LEROBOT_VENV)/bin/python -m pip install -q --upgrade pip
	$(LEROBOT_VENV)/bin/python -m pip install -q 'lerobot[pusht,training,evaluation,diffusion]==0.6.1' 'torch<2.12' 'numpy<2.3' \
		'pytest>=8' 'pytest-timeout>=2.3' 'pytest-xdist>=3.6' -e '.[warp,gym]' -e plugins/lerobot_env_mjx_pusht
	touch $(LEROBOT_STAMP)

# the Python 3.12 the LeRobot venv is made with (docs/lerobot.md's by-hand install uses it)
python312:
	@test -n "$(PYTHON312)" || { echo "no Python 3.12 on the PATH or under ~/.pyenv/versions: set PYTHON312=/path/to/python3.12" >&2; exit 2; }
	@echo $(PYTHON312)

test-lerobot: $(LEROBOT_STAMP)
	$(LEROBOT_VENV)/bin/python -m pytest -q tests/lerobot

# The matrix's second leg, by hand (not in `make test`: CI's time): a venv of the newest versions pyproject.toml's
# ranges allow (MuJoCo 4.0 with MJX-JAX; Python 3.12 where found), no lock, then the quick loop one test file a
# process (a crash or a hang is that file's alone, cut at 600 s: docs/install.md says why) and the fidelity test.
# Each run resolves afresh, so the venv is remade every time; the last line lists the files that failed.
NEWEST_VENV := .venv-newest
test-newest:
	rm -rf $(NEWEST_VENV)
	$(or $(PYTHON312),$(PYTHON)) -m venv $(NEWEST_VENV)
	$(NEWEST_VENV)/bin/python -m pip install -q --upgrade pip
	$(NEWEST_VENV)/bin/python -m pip install -q --upgrade --upgrade-strategy eager -e '.[warp,gym,video,train,test]'
	$(NEWEST_VENV)/bin/python -m pip check
	$(NEWEST_VENV)/bin/python -c "import sys, mujoco, jax, numpy; print('newest leg: Python', sys.version.split()[0], \
		'mujoco', mujoco.__version__, 'jax', jax.__version__, 'numpy', numpy.__version__)"
	@failed=; for f in tests/test_*.py; do \
		timeout 600 $(NEWEST_VENV)/bin/python -m pytest -q -p no:cacheprovider -n 0 -m "not slow" $$f >$(NEWEST_VENV)/last.log 2>&1; \
		rc=$$?; echo "$$f rc=$$rc $$(tail -n 1 $(NEWEST_VENV)/last.log)"; \
		[ $$rc = 0 ] || [ $$rc = 5 ] || failed="$$failed $$f"; done; \
	timeout 900 $(NEWEST_VENV)/bin/python -m pytest -q -p no:cacheprovider -n 0 -m slow tests/test_compare.py || failed="$$failed tests/test_compare.py"; \
	if [ -n "$$failed" ]; then echo "make test-newest: failed:$$failed"; exit 1; fi

bench: $(STAMP)
	$(BIN)/python -m benchmarks.harness

clean:
	rm -rf $(VENV) $(LEROBOT_VENV) $(NEWEST_VENV) .jax_cache site outputs/scene outputs/sweep
