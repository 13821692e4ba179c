#!/usr/bin/env bash
# Issue 56's runs in one hold of 4 GPUs (see ../shared/gpu/README.md for the wheels; jax 0.10.2 in $HOME/jsite):
#   bash benchmarks/train_devices.sh start    # the whole plan in the background, in its own process session
#   bash benchmarks/train_devices.sh watch    # back to back: copies what is finished into $OUT every 15 s
# A hold ends when its device time does, so the plan runs its most needed figures first and every run is copied
# back as it finishes (a watch cut at its limit still returns what is under $OUT):
#   1. which PPO trains on several GPUs (2 each, side by side; both crashed before, notebooks lead12-13):
#      MJX-Warp with XLA capturing its CUDA graph (MJX_PUSHT_ENV_GRAPH_MODE=JAX), and MJX-JAX;
#   2. DAgger from pixels on gym-pusht's task, 4 GPUs, seed 0, 5 minutes (must reach 90%);
#   3. PPO from state on it, 4 GPUs, seed 0, 3 minutes (must reach 95%), on the first probe that trained;
#   4. side by side, for the throughput against one GPU: PPO on GPU 0 and on GPUs 1-2, DAgger from pixels on GPU 3;
#   5. PPO seed 1 on 4 GPUs; 6. DAgger from pixels seed 1 on 4 GPUs.
# Weak scaling (benchmarks/train_scaling.py --per-device): each GPU one GPU's episodes and minibatch share.
# DRY=1 prints the commands instead of running them (a check of the plan's order and choices on any machine).
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
root=$PWD runs=$HOME/runs
mkdir -p "$runs"
case "${1:-}" in
  start)
    (cd "$runs" && setsid nohup bash -c 'echo $$ > "$0"; exec "$@"' "$runs/devices.pid" \
      bash "$root/benchmarks/train_devices.sh" plan > "$runs/devices.log" 2>&1 < /dev/null &)
    sleep "${WAIT:-20}"; cp "$runs/devices.log" "${OUT:-/tmp}/" ;;
  plan)
    export PYTHONPATH=$HOME/jsite:$HOME/site:$root PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
    export MJX_PUSHT_JAX_CACHE=$HOME/jax_cache NCCL_NVLS_ENABLE=0 TORCH_SYMM_MEM_DISABLE_MULTICAST=1 NVSHMEM_DISABLE_NVLS=1
    cd "$runs" || exit 1
    run() { echo "$(date +%T) \$ $*"; [ -n "${DRY:-}" ] && return "${DRY_RC:-0}"; "$@"; }
    common="--task gym-pusht --keep best --no-progress --no-rerun --record 0"
    ppo="--algo ppo --envs 8192 --batch 512 --timesteps 400000000 --iterations 80 --minutes 3 $common"
    px="--obs pixels_agent_pos --hidden 1024,1024,1024 --fit-steps 10000 --batch 4096 --beta-decay 0.7 --first-fits 4"
    px="$px --iterations 300 --minutes 5 --image-steps 4000 --image-batch 512 --envs 4096 --max-samples 8000000 $common"
    # scale GPUS GOAL OUT COUNT PER-DEVICE-FLAGS ENV-ASSIGNMENTS TRAIN-ARGS...: one train_scaling run
    scale() {
      local gpus=$1 goal=$2 out=$3 n=$4 per=$5 extra=$6; shift 6
      # shellcheck disable=SC2086  # extra: zero or more VAR=value words
      run env ${gpus:+CUDA_VISIBLE_DEVICES=$gpus} $extra python3 -m benchmarks.train_scaling --goal "$goal" \
        --out "$out" --devices "$n" --per-device "$per" -- "$@"
    }
    ppo_per=envs,batch,timesteps px_per=envs,batch,image-batch,max-samples
    # 1. the probes: 30 s of training each on 2 GPUs (one GPU's share each: 2 x 8192 envs), a hang ended by timeout
    for probe in "0,1 mjx-warp MJX_PUSHT_ENV_GRAPH_MODE=JAX probe-warp-jax" "2,3 mjx-jax - probe-jax"; do
      read -r gpus backend extra name <<< "$probe"; [ "$extra" = - ] && extra=""
      # shellcheck disable=SC2086  # the recipe: a list of flags
      (run env CUDA_VISIBLE_DEVICES=$gpus $extra timeout 300 python3 -m mjx_pusht train --backend $backend $ppo \
         --envs 16384 --batch 1024 --timesteps 800000000 --minutes 0.5 --devices 2 --out $name > $name.log 2>&1
       echo "exit $?" >> $name.log) &
    done
    wait
    tail -n 3 probe-*.log
    if grep -q "^exit 0" probe-warp-jax.log; then ppo_backend=mjx-warp ppo_env=MJX_PUSHT_ENV_GRAPH_MODE=JAX
    elif grep -q "^exit 0" probe-jax.log; then ppo_backend=mjx-jax ppo_env=""
    else ppo_backend="" ppo_env=""; fi
    echo "PPO on several GPUs: ${ppo_backend:-neither probe trained}"
    # shellcheck disable=SC2086  # the recipes: lists of flags
    {
    # 2. DAgger from pixels, 4 GPUs, seed 0
    scale "" 0.9 px-s0 4 $px_per "" --backend mjx-warp $px --seed 0 > px-s0.log 2>&1
    # 3. PPO, 4 GPUs, seed 0
    [ -n "$ppo_backend" ] && scale "" 0.95 ppo-s0 4 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 0 > ppo-s0.log 2>&1
    # 4. one GPU and two, side by side (PPO on GPU 0 and GPUs 1-2, pixels on GPU 3; no PPO: pixels on 0 and 1-2)
    if [ -n "$ppo_backend" ]; then
      scale 0 0.95 ppo-s0 1 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 0 > ppo-s0-1.log 2>&1 &
      scale 1,2 0.95 ppo-s0 2 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 0 > ppo-s0-2.log 2>&1 &
      scale 3 0.9 px-s0 1 $px_per "" --backend mjx-warp $px --seed 0 > px-s0-1.log 2>&1 &
    else
      scale 0 0.9 px-s0 1 $px_per "" --backend mjx-warp $px --seed 0 > px-s0-1.log 2>&1 &
      scale 1,2 0.9 px-s0 2 $px_per "" --backend mjx-warp $px --seed 0 > px-s0-2.log 2>&1 &
    fi
    wait
    # 5. and 6. the second seeds
    [ -n "$ppo_backend" ] && scale "" 0.95 ppo-s1 4 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 1 > ppo-s1.log 2>&1
    scale "" 0.9 px-s1 4 $px_per "" --backend mjx-warp $px --seed 1 > px-s1.log 2>&1
    }
    echo "$(date +%T) plan done" ;;
  watch)
    # every 15 s until the plan ends or WAIT (570) passes: the plan's log, each run's logs, curves and summaries in
    # one tar (not the resume checkpoints' rings, the eval tables or recordings), and each finished run's policy
    out=${OUT:?watch copies into \$OUT}; t=0
    while :; do
      (cd "$runs" && tar czf "$out/devices.tgz" --exclude='*.msgpack' --exclude='*.f32' --exclude='*.parquet' \
        --exclude='*.rrd' --exclude='checkpoint*' ./*.log $(ls -d probe-* px-* ppo-* 2>/dev/null | grep -v '\.log$') 2>/dev/null)
      for p in "$runs"/*/devices-*/policy.msgpack; do
        [ -f "$p" ] && [ -f "$(dirname "$p")/summary.json" ] && grep -q '"eval"' "$(dirname "$p")/summary.json" && \
          cp "$p" "$out/$(basename "$(dirname "$(dirname "$p")")")-$(basename "$(dirname "$p")").msgpack"
      done
      kill -0 "$(cat "$runs/devices.pid" 2>/dev/null)" 2>/dev/null || break
      [ "$t" -ge "${WAIT:-570}" ] && break
      sleep 15; t=$((t + 15))
    done
    nvidia-smi --query-gpu=index,utilization.gpu,memory.used --format=csv > "$out/nvidia-smi.csv" 2>&1
    tail -n 4 "$runs/devices.log"; true ;;
  *) echo "usage: train_devices.sh start|watch (issue 56's plan on a 4-GPU machine)" >&2; exit 2 ;;
esac
