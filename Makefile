# Two commands do all the set-up on a fresh machine (Python 3.11+ with venv):
#   make run    - the main job: a 4096-seed sweep on the fastest faithful backend here
#   make test   - the test suite
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export MJX_PUSHT_JAX_CACHE ?= $(CURDIR)/.jax_cache

.PHONY: run test scene bench clean

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

bench: $(STAMP)
	$(BIN)/python -m benchmarks.harness

clean:
	rm -rf $(VENV) .jax_cache outputs/scene outputs/sweep
