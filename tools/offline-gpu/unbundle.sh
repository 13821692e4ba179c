#!/usr/bin/env bash
# There, on the GPU host, in the repository's root: unpack what tools/offline-gpu/bundle.sh packed here and
# install it (docs/offline-gpu.md). Usage: bash tools/offline-gpu/unbundle.sh
# the folders tools/offline-gpu/bundle.sh packed here (8 calls of 55 MiB for MuJoCo, Warp, Brax and jax 0.10.2),
# every call but the last having run `mkdir -p ~/b && cp .gpu-all/K/* ~/b/`: each wheel set present installed
# (MuJoCo, Warp, Brax into ~/site; jax 0.10.2 into ~/jsite, first on the path; LeRobot into ~/site), demos
# into ~/diffusion (diffusion_pusht.sh's RUNS)
set -uo pipefail
export PYTHONPATH=$HOME/site:$PWD  # the repository's root, before the cd below
mkdir -p "$HOME/b" && cp .gpu-all/*/* "$HOME/b/" 2>/dev/null; cd "$HOME/b" && cat bundle.part.* | tar x || exit 1
if [ -d .gpu ]; then mkdir -p "$HOME/stash" && cp .gpu/*/* "$HOME/stash/" && (cd "$HOME/stash" && \
  cat warp.part* > "$(cat warp.name)" && python3 -m pip install -q --no-index --no-deps --no-compile \
  --no-cache-dir --target "$HOME/site" ./*.whl) || exit 1; fi
if [ -d .gpu-jax ]; then mkdir -p "$HOME/jstash" && cp .gpu-jax/*/* "$HOME/jstash/" && (cd "$HOME/jstash" && \
  cat jaxlib.part0* > jaxlib-0.10.2-cp312-cp312-manylinux_2_27_x86_64.whl && \
  cat pjrt.part0* > jax_cuda13_pjrt-0.10.2-py3-none-manylinux_2_27_x86_64.whl && rm -f ./*.part0* && \
  python3 -m pip install -q --no-index --no-deps --no-compile --target "$HOME/jsite" ./*.whl) || exit 1; fi
if [ -d .gpu-lerobot ]; then mkdir -p "$HOME/lr" && cp .gpu-lerobot/*/* "$HOME/lr/" && (cd "$HOME/lr" && \
  cat part.* | tar x && python3 -m pip install -q --no-index --no-deps --no-compile --target "$HOME/site" \
  "$HOME"/lr/*.whl) || exit 1; fi
if [ -d .gpu-demos ]; then mkdir -p "$HOME/diffusion" && cp -r .gpu-demos/* "$HOME/diffusion/"; fi
jsite=""; [ -d "$HOME/jsite" ] && jsite=$HOME/jsite:
PYTHONPATH=$jsite$PYTHONPATH python3 -c "import jax, mujoco, warp; from mujoco import mjx
print(jax.__version__, mujoco.__version__, warp.__version__, jax.devices())
if jax.__version__ != '0.10.2':  # the machine's own jax, not the pinned one (the 6 .gpu-all parts hold none)
    print(f'unbundle: WARNING jax {jax.__version__} here, not the pinned 0.10.2: carry .gpu-jax too (notebook lead23)')"
ls "$HOME/diffusion" 2>/dev/null; true
