#!/usr/bin/env bash
# LeRobot on a lent GPU machine (one H100): lerobot-eval of one policy on gym-pusht and on the plugin's batch,
# and `mjx-pusht demos` writing 1,000 and 10,000 expert episodes. Results and logs go under $OUT.
# Usage there, from the repository root, with lerobot 0.6.1, gym-pusht, this project and its plugin installed
# (tools/offline-gpu/lerobot_wheels.sh carries the wheels to $HOME/site):  bash benchmarks/lerobot_gpu.sh [STAGE ...]
set -uo pipefail
export PYTHONPATH=$HOME/site:$PWD PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false HF_HUB_OFFLINE=1 WANDB_MODE=disabled
export MJX_PUSHT_JAX_CACHE=${MJX_PUSHT_JAX_CACHE:-$HOME/jax_cache}
OUT=${OUT:-outputs/bench-lerobot}
mkdir -p "$OUT/results"
PY=${PY:-python3}
stages=${*:-policy eval-mjx eval-pusht demos-1k demos-10k}
for stage in $stages; do
  case "$stage" in
    policy) $PY tests/lerobot/tiny_policy.py "$OUT/policy" --device cuda > "$OUT/policy.log" 2>&1 ;;
    eval-mjx) $PY -m benchmarks.lerobot_eval --policy "$OUT/policy" --env mjx_pusht --episodes 500 --batch 500 \
                --out "$OUT/eval" --json "$OUT/results/lerobot-eval.json" > "$OUT/eval-mjx.log" 2>&1 ;;
    eval-pusht) $PY -m benchmarks.lerobot_eval --policy "$OUT/policy" --env pusht --episodes 500 --batch 500 \
                --out "$OUT/eval" --json "$OUT/results/lerobot-eval.json" > "$OUT/eval-pusht.log" 2>&1 ;;
    demos-1k|demos-10k)
      n=1000; [ "$stage" = demos-10k ] && n=10000
      t0=$(date +%s.%N)
      $PY -m mjx_pusht demos --seeds $n --out "$HOME/demos-$n" --replace > "$OUT/$stage.log" 2>&1
      rc=$?; t1=$(date +%s.%N)
      $PY - "$n" "$rc" "$t0" "$t1" "$HOME/demos-$n" >> "$OUT/results/demos.jsonl" <<'PYEOF'
import json, subprocess, sys, time
n, rc, t0, t1, root = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
info = json.load(open(f"{root}/meta/info.json")) if rc == 0 else {}
try:
    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True, text=True).stdout.strip()
except FileNotFoundError:
    gpu = None
du = subprocess.run(["du", "-sb", root], capture_output=True, text=True).stdout.split()[:1]
print(json.dumps({"command": f"mjx-pusht demos --seeds {n}", "rc": rc, "wall_s": t1 - t0, "episodes": info.get("total_episodes"),
                  "frames": info.get("total_frames"), "bytes": int(du[0]) if du else None, "gpu": gpu,
                  "date": time.strftime("%Y-%m-%d")}))
PYEOF
      ;;
    *) echo "unknown stage $stage (policy eval-mjx eval-pusht demos-1k demos-10k)"; exit 2 ;;
  esac
  echo "$stage done: rc=$?"
done
