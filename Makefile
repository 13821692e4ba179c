# Two commands do all the set-up on a fresh machine (Python 3.11+ with venv):
#   make run    - the main job: a 4096-seed sweep on the fastest faithful backend here
#   make test   - everything CI checks: the test suite, the docs site built strict, and LeRobot's own tools
#                 on the plugin (tests/lerobot/, in a Python 3.12 venv of its own: lerobot 0.6.1's pins)
# Parts: make pytest (the suite alone), make docs, make test-lerobot.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export MJX_PUSHT_JAX_CACHE ?= $(CURDIR)/.jax_cache

# lerobot 0.6.1 needs Python >= 3.12, torch < 2.12 and numpy < 2.3: its tests get a venv of their own
PYTHON312 ?= $(shell for p in python3.12 $$(ls -d $$HOME/.pyenv/versions/3.12*/bin/python3.12 2>/dev/null); do \
	$$p -V >/dev/null 2>&1 && { echo $$p; break; }; done)
LEROBOT_VENV := .venv-lerobot
LEROBOT_STAMP := $(LEROBOT_VENV)/.installed

.PHONY: run test pytest test-lerobot docs scene bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[warp,gym,video,train,test]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/mjx-pusht sweep

scene: $(STAMP)
	$(BIN)/mjx-pusht scene

test: pytest docs test-lerobot

pytest: $(STAMP)
	$(BIN)/python -m pytest -q

$(VENV)/.docs-installed: $(STAMP)
	$(BIN)/python -m pip install -q -e '.[docs]'
	touch $@

docs: $(VENV)/.docs-installed
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

$(LEROBOT_STAMP): pyproject.toml plugins/lerobot_env_mjx_pusht/pyproject.toml
	@test -n "$(PYTHON312)" || { echo "make test-lerobot needs Python 3.12 (lerobot 0.6.1 requires it): set PYTHON312=/path/to/python3.12"; exit 2; }
	$(PYTHON312) -m venv $(LEROBOT_VENV)
	$(LEROBOT_VENV)/bin/python -m pip install -q --upgrade pip
	$(LEROBOT_VENV)/bin/python -m pip install -q 'lerobot[pusht,training,evaluation]==0.6.1' 'torch<2.12' 'numpy<2.3' \
		'pytest>=8' 'pytest-timeout>=2.3' -e '.[warp,gym]' -e plugins/lerobot_env_mjx_pusht
	touch $(LEROBOT_STAMP)

test-lerobot: $(LEROBOT_STAMP)
	$(LEROBOT_VENV)/bin/python -m pytest -q tests/lerobot

bench: $(STAMP)
	$(BIN)/python -m benchmarks.harness

clean:
	rm -rf $(VENV) $(LEROBOT_VENV) .jax_cache site outputs/scene outputs/sweep
