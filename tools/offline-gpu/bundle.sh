#!/usr/bin/env bash
# Here, before a hold: the ignored folders a hold needs (wheel sets, demos) as one tar in 55 MiB parts, each in a
# folder .gpu-all/K of its own, so a device call carries one (the 64 MiB a call carries hold a part and the tree,
# 8 MB once outputs/ is moved aside for the carrying calls: `mv outputs ../outputs-aside`, back after; 59 MiB parts
# no longer fit beside it, lead29).
#   bash tools/offline-gpu/bundle.sh .gpu .gpu-jax              # MuJoCo, Warp, Brax and jax 0.10.2 (training on GPUs)
#   bash tools/offline-gpu/bundle.sh .gpu .gpu-lerobot .gpu-demos/demos-2000  # LeRobot and the expert's demos
# There: every call but the last `mkdir -p ~/b && cp .gpu-all/K/* ~/b/`, the last `bash tools/offline-gpu/unbundle.sh`.
set -euo pipefail
cd "$(dirname "$0")/../.."
[ $# -gt 0 ] || { echo "usage: bundle.sh FOLDER... (e.g. .gpu .gpu-jax)" >&2; exit 2; }
for d in "$@"; do [ -d "$d" ] || { echo "bundle.sh: no folder $d" >&2; exit 1; }; done
git check-ignore -q .gpu-all/x || { echo "bundle.sh: .gpu-all/ is not ignored here (echo /.gpu-all/ >> .git/info/exclude)" >&2; exit 1; }
tmp=$(mktemp -d)
tar cf - "$@" | split -b 55M -d - "$tmp/bundle.part."
rm -rf .gpu-all && mkdir .gpu-all
k=0; for f in "$tmp"/bundle.part.*; do k=$((k + 1)); mkdir .gpu-all/$k && mv "$f" .gpu-all/$k/; done
rmdir "$tmp"
echo "$k parts in .gpu-all/1..$k ($(du -sh .gpu-all | cut -f1)): $k calls, the last running tools/offline-gpu/unbundle.sh"
