#!/usr/bin/env bash
# Here (a machine with a registry), from the repository's root: the pinned JAX for a GPU host whose own JAX is
# another version, as .gpu-jax/1 (jax, the CUDA 13 plugin, jaxlib and the PJRT plugin cut into 50 MiB parts named as
# unbundle.sh joins them). PPO over several GPUs or processes crashed in XLA's compile under jax 0.11.2, every time
# it was tried (notebooks lead12, lead23, lead25); the pinned jax compiled it. Then `bundle.sh .gpu .gpu-jax`.
set -euo pipefail
cd "$(dirname "$0")/../.."
v=${JAX_VERSION:-0.10.2}
grep -qx '/.gpu-jax/' .git/info/exclude 2>/dev/null || echo '/.gpu-jax/' >> .git/info/exclude
tmp=$(mktemp -d)
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_27_x86_64 --platform manylinux_2_28_x86_64 --platform manylinux2014_x86_64 -d "$tmp" \
  "jax==$v" "jaxlib==$v" "jax-cuda13-plugin==$v" "jax-cuda13-pjrt==$v" 2> >(grep -v '^WARNING: Location' >&2)
rm -rf .gpu-jax && mkdir -p .gpu-jax/1
mv "$tmp"/jax-"$v"-*.whl "$tmp"/jax_cuda13_plugin-*.whl .gpu-jax/1/
split -b 50M -d -a 2 "$tmp"/jaxlib-*.whl .gpu-jax/1/jaxlib.part
split -b 50M -d -a 2 "$tmp"/jax_cuda13_pjrt-*.whl .gpu-jax/1/pjrt.part
rm -rf "$tmp"
du -sh .gpu-jax; echo "now: bash tools/offline-gpu/bundle.sh .gpu .gpu-jax"
