#!/usr/bin/env bash
# The wheels lerobot-eval and lerobot-train (ACT, and Diffusion Policy: diffusers, accelerate) need on a GPU machine
# that has Python 3.12, torch 2.11 (CUDA), jax, numpy, pyarrow, Pillow, tqdm and matplotlib but no package registry,
# beside this project's own (.gpu/: docs/offline-gpu.md): downloaded here, tarred and cut into parts (one a device
# call) as large as a call carries beside the tree (64 MiB in all), written to .gpu-lerobot/K/.
#   bash tools/offline-gpu/lerobot_wheels.sh            # then, per part K, carry [".gpu-lerobot/K"] and run
#   mkdir -p $HOME/lr && cp .gpu-lerobot/K/* $HOME/lr/
# and after the last part:
#   cd $HOME/lr && cat part.* | tar x && python3 -m pip install -q --no-index --no-deps --no-compile \
#     --target $HOME/site ./*.whl && cd - && PYTHONPATH=$HOME/site:$PWD python3 -c "import lerobot, gym_pusht, av"
set -euo pipefail
SPECS="lerobot==0.6.1 torchvision==0.26.0 opencv-python-headless==4.13.0.92 av==15.1.0 gym-pusht==0.1.8
pymunk==6.11.1 cffi==2.1.1 pycparser==3.12 pygame==2.6.1 shapely==2.2.0 gymnasium==1.4.0 cloudpickle==3.1.3
farama-notifications==0.0.6 einops==0.8.2 draccus==0.11.6 mergedeep==1.3.4 pyyaml==6.0.4 toml==0.10.2
typing-inspect==0.9.0 mypy-extensions==1.2.0 huggingface-hub==1.33.0 hf-xet==1.8.0 httpx==0.28.1 httpcore==1.0.9
h11==0.16.0 anyio==4.16.0 idna==3.20 certifi==2026.10.19.post1 requests==2.34.2 urllib3==2.8.0
charset-normalizer==3.5.2 safetensors==0.8.0 termcolor==3.3.0 datasets==4.8.5 dill==0.4.1 multiprocess==0.70.19
xxhash==4.1.0 pandas==2.3.3 pytz==2026.6 tzdata==2026.6 aiohttp==3.14.5 aiohappyeyeballs==2.7.1
aiosignal==1.4.0 frozenlist==1.8.0 multidict==7.2.1 propcache==0.5.4 yarl==1.25.1 attrs==26.1.0 jsonlines==4.0.0
accelerate==1.15.0 psutil==7.2.2 diffusers==0.39.0 importlib-metadata==10.2.0 zipp==4.1.2 regex==2026.11.19"
root=$(git rev-parse --show-toplevel)
cd "$root"
exclude=$(git rev-parse --git-path info/exclude)  # a worktree's is its main checkout's
grep -qx '/.gpu-lerobot/' "$exclude" 2>/dev/null || echo '/.gpu-lerobot/' >> "$exclude"
rm -rf .gpu-lerobot && mkdir -p .gpu-lerobot/dl
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_24_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform manylinux1_x86_64 \
  -d .gpu-lerobot/dl $SPECS 2> >(grep -v '^WARNING: Location' >&2)
# the plugin as a wheel too: LeRobot finds plugins by their installed distribution's name
python3 -m pip wheel -q --no-deps --ignore-requires-python -w .gpu-lerobot/dl plugins/lerobot_env_mjx_pusht
(cd .gpu-lerobot/dl && tar cf ../all.tar ./*.whl)
# a call carries 64 MiB with the tree (its tracked and not ignored files): a part is what is left, less 2 MiB
tree=$(git ls-files -z --cached --others --exclude-standard | xargs -0 stat -c %s | awk '{s += $1} END {print s}')
part=$(( (64 * 1048576 - tree) / 1048576 - 2 ))
split -b "${part}m" -d .gpu-lerobot/all.tar .gpu-lerobot/part.
n=0
for p in .gpu-lerobot/part.*; do n=$((n + 1)); mkdir -p ".gpu-lerobot/$n"; mv "$p" ".gpu-lerobot/$n/"; done
rm -rf .gpu-lerobot/dl .gpu-lerobot/all.tar
du -sm .gpu-lerobot/*
echo "$n device calls, one a part of at most $part MiB (see the top of this script)"
