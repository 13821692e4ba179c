# Two commands do all the set-up on a fresh machine (Python 3.11+ with venv):
#   make run    - the main job: a 4096-seed sweep on the fastest faithful backend here
#   make test   - the test suite
#   make docs   - the docs site (site/), built strict: a broken link or reference fails it
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export MJX_PUSHT_JAX_CACHE ?= $(CURDIR)/.jax_cache

.PHONY: run test docs scene bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[warp,gym,video,train,test]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/mjx-pusht sweep

scene: $(STAMP)
	$(BIN)/mjx-pusht scene

test: $(STAMP)
	$(BIN)/python -m pytest -q

$(VENV)/.docs-installed: $(STAMP)
	$(BIN)/python -m pip install -q -e '.[docs]'
	touch $@

docs: $(VENV)/.docs-installed
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

bench: $(STAMP)
	$(BIN)/python -m benchmarks.harness

clean:
	rm -rf $(VENV) .jax_cache site outputs/scene outputs/sweep
