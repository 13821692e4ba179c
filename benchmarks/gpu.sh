#!/usr/bin/env bash
# Measurements on a lent GPU machine (see ../shared/gpu/README.md for carrying the wheels).
# Usage there: bash benchmarks/gpu.sh STAGE TIER   (logs and results go under $OUT)
set -uo pipefail
stage=$1; tier=${2:-h100}
export PYTHONPATH=$HOME/site:$PWD PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
export MJX_PUSHT_JAX_CACHE=$HOME/jax_cache
mkdir -p "$OUT/results"
case "$stage" in
  warp)   python3 -m benchmarks.harness --tier "$tier-warp" --backends cpu,mjx-warp --cpu-batches 4096,65536 \
            --batches 1024,4096,16384,65536 --repeats 2 --out "$OUT/results" 2>&1 | tee "$OUT/$stage.log" ;;
  warp-tight) python3 -m benchmarks.harness --tier "$tier-warp-tight" --backends cpu,mjx-warp --cpu-batches 65536 \
            --batches 4096,65536,131072,262144 --repeats 2 --e2e 1000000 --e2e-chunk 262144 --out "$OUT/results" 2>&1 | tee "$OUT/$stage.log" ;;
  e2e)    python3 -m benchmarks.harness --tier "$tier-e2e" --backends mjx-warp --batches 65536 --repeats 1 \
            --e2e 1000000 --e2e-chunk 65536 --out "$OUT/results" 2>&1 | tee "$OUT/$stage.log" ;;
  jax)    python3 -m benchmarks.harness --tier "$tier-jax" --backends mjx-jax --batches 1024,4096,16384,65536 \
            --repeats 2 --e2e 1000000 --out "$OUT/results" 2>&1 | tee "$OUT/$stage.log" ;;
  compare-warp) python3 -m mjx_pusht compare --seeds 4096 --backend mjx-warp --no-root-cause \
            --out "$OUT/compare-mjx-warp" 2>&1 | tee "$OUT/$stage.log" ;;
  compare-jax) python3 -m mjx_pusht compare --seeds 4096 --backend mjx-jax --out "$OUT/compare-mjx-jax" 2>&1 | tee "$OUT/$stage.log" ;;
  profile) python3 -m benchmarks.profile_warp --batch 65536 --rate-batches 65536 \
            --out "$OUT/results/$tier-profile.json" 2>&1 | tee "$OUT/$stage.log" ;;
  tier)   python3 -m benchmarks.harness --tier "$tier" --backends cpu,mjx-warp --cpu-batches 65536 \
            --batches 4096,65536,131072,262144 --repeats 3 --e2e 1000000 --e2e-chunk "${CHUNK:-65536}" \
            --out "$OUT/results" > "$OUT/$stage.log" 2>&1 ;;
  sharded) python3 -m benchmarks.harness --tier "$tier" --backends cpu,mjx-warp --cpu-batches 65536 \
            --batches 65536,131072,262144 --repeats 3 --device-counts 1,2 --e2e 1000000 --e2e-chunk 131072 \
            --out "$OUT/results" > "$OUT/$stage.log" 2>&1 ;;
  modes)  python3 -m benchmarks.warp_modes --batch 65536 --out "$OUT/results/$tier-warp-modes.json" \
            --only "${ONLY:-cold-lazy,cold,warm,rate-default,cold-deterministic,rate-deterministic,trace-default}" \
            --cache-root "$HOME/modes-cache" --log-dir "$OUT/modes" --timeout "${VARIANT_TIMEOUT:-300}" > "$OUT/$stage.log" 2>&1 ;;
  batches) python3 -m benchmarks.harness --tier "$tier-batches" --backends mjx-warp \
            --batches 32768,49152,65536,98304 --repeats 3 --out "$OUT/results" > "$OUT/$stage.log" 2>&1 ;;
  task-bench) python3 -m benchmarks.harness --tier "$tier-task" --backends mjx-warp --batches 4096,65536 --repeats 2 \
            --closed-loop 100 --box-box-both --out "$OUT/results" > "$OUT/$stage.log" 2>&1 ;;
  compare-both) python3 -m mjx_pusht compare --seeds 4096 --backend mjx-warp --no-root-cause \
            --out "$OUT/compare-mjx-warp" > "$OUT/compare-warp.log" 2>&1
          python3 -m mjx_pusht compare --seeds 4096 --backend mjx-jax --out "$OUT/compare-mjx-jax" > "$OUT/compare-jax.log" 2>&1 ;;
  task-study) python3 -m mjx_pusht.studies kv-expert --seeds 4096 --backend mjx-warp --out "$OUT/kv-expert" \
            > "$OUT/kv-expert.log" 2>&1
          python3 -m mjx_pusht compare --controller expert --reset task --seeds 4096 --backend mjx-warp \
            --out "$OUT/compare-task-mjx-warp" > "$OUT/compare-task.log" 2>&1 ;;
  *) echo "unknown stage $stage" >&2; exit 2 ;;
esac
