#!/usr/bin/env bash
# Training on several GPUs, a plan of runs for one hold of 4 GPUs (the wheels carried as docs/offline-gpu.md says;
# jax 0.10.2 in $HOME/jsite):
#   bash tools/offline-gpu/train_devices.sh start [PLAN]  # a plan (default: plan, below) in the background, its own session
#   bash tools/offline-gpu/train_devices.sh watch    # back to back: copies what is finished into $OUT every 15 s
# A hold ends when its device time does, so the plan runs its most needed figures first and every run is copied
# back as it finishes (a watch cut at its limit still returns what is under $OUT). Session 15's hold (notebook
# lead15): PPO on MJX-JAX scaled (3.8x on 4 H200s) but cannot reach 95% in 3 minutes; MJX-Warp failed on several GPUs
# (PPO with XLA capturing the graph; DAgger from pixels with error 904, since changed). This plan:
#   1. probes, 2 GPUs each, side by side: DAgger from pixels on MJX-Warp (a tiny run reaching a student rollout), and
#      PPO on MJX-Warp with a graph per device (MJX_PUSHT_ENV_GRAPH_MODE=WARP: the staged default shares one graph
#      between the devices, lead15), then, if that fails, without a graph (NONE);
#   2. DAgger from pixels on gym-pusht's task, 4 GPUs, seed 0, 5 minutes (must reach 90%), if its probe trained;
#   3. PPO from state on it, 4 GPUs, seed 0, 3 minutes (must reach 95%): MJX-Warp in the first graph mode whose
#      probe trained, else MJX-JAX;
#   4. the second seeds on 4 GPUs (each must-show is two seeds);
#   5. side by side, against one GPU: pixels on GPU 0 and on GPUs 1-2, PPO on GPU 3; 6. PPO on 2 GPUs.
# Weak scaling (benchmarks/train_scaling.py --per-device): each GPU one GPU's episodes and minibatch share.
# DRY=1 prints the commands instead of running them (a check of the plan's order and choices on any machine).
set -uo pipefail
cd "$(dirname "$0")/../.." || exit 1
root=$PWD runs=$HOME/runs
mkdir -p "$runs"
case "${1:-}" in
  start)
    (cd "$runs" && setsid nohup bash -c 'echo $$ > "$0"; exec "$@"' "$runs/devices.pid" \
      bash "$root/tools/offline-gpu/train_devices.sh" "${2:-plan}" > "$runs/devices.log" 2>&1 < /dev/null &)
    sleep "${WAIT:-20}"; cp "$runs/devices.log" "${OUT:-/tmp}/" ;;
  plan|ppo-wide|ppo-apart|ppo-procs|pair)
    export PYTHONPATH=$HOME/jsite:$HOME/site:$root PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
    export MJX_PUSHT_JAX_CACHE=$HOME/jax_cache NCCL_NVLS_ENABLE=0 TORCH_SYMM_MEM_DISABLE_MULTICAST=1 NVSHMEM_DISABLE_NVLS=1
    cd "$runs" || exit 1
    run() { echo "$(date +%T) \$ $*"; [ -n "${DRY:-}" ] && return "${DRY_RC:-0}"; "$@"; }
    # FLAGS... with a later flag in place of an earlier one of the same name (the CLI refuses a flag given twice):
    # a probe's sizes over the recipe's
    over() { python3 -c 'import sys
a, out, i = sys.argv[1:], [], 0
while i < len(a):
    n = 2 if a[i].startswith("--") and i + 1 < len(a) and not a[i + 1].startswith("--") else 1
    if not (a[i].startswith("--") and a[i] in a[i + n:]):
        out += a[i:i + n]
    i += n
print(" ".join(out))' "$@"; }
    common="--task gym-pusht --keep best --no-progress --no-rerun --record 0"
    # each run ends at its goal rate (--until) or its budget: the minutes to the goal are the figure, and a run
    # that stops there leaves the hold's time to the next one
    ppo="--algo ppo --envs 8192 --batch 512 --timesteps 400000000 --iterations 80 --minutes 3 --until 0.95 $common"
    px="--obs pixels_agent_pos --hidden 1024,1024,1024 --fit-steps 10000 --batch 4096 --beta-decay 0.7 --first-fits 4"
    px="$px --iterations 300 --minutes 5 --until 0.9 --image-steps 4000 --image-batch 512 --envs 4096 --max-samples 8000000 $common"
    # scale GPUS GOAL OUT COUNT PER-DEVICE-FLAGS ENV-ASSIGNMENTS TRAIN-ARGS...: one train_scaling run
    scale() {
      local gpus=$1 goal=$2 out=$3 n=$4 per=$5 extra=$6; shift 6
      # shellcheck disable=SC2086  # extra: zero or more VAR=value words
      run env ${gpus:+CUDA_VISIBLE_DEVICES=$gpus} $extra python3 -m benchmarks.train_scaling --goal "$goal" \
        --out "$out" --devices "$n" --per-device "$per" -- "$@"
    }
    ppo_per=envs,batch,timesteps px_per=envs,batch,image-batch,max-samples
    if [ "$1" = ppo-wide ]; then
      # PPO on MJX-Warp at ENVS worlds a GPU (default 16,384, twice the plan's), MINUTES long with no --until, for a
      # steady rate: the plan's 4-GPU PPO ran 2.85x one GPU's (its runs ended in under a minute, compiles included)
      e=${ENVS:-16384}
      w="--algo ppo --envs $e --batch $((e / 16)) --timesteps $((e * 48828)) --iterations 80 --minutes ${MINUTES:-1.5}"
      # shellcheck disable=SC2086  # the recipe: a list of flags
      {
      scale 0 0.95 wide 1 $ppo_per MJX_PUSHT_ENV_GRAPH_MODE=WARP --backend mjx-warp $w $common > wide-1.log 2>&1 &
      scale 1,2 0.95 wide 2 $ppo_per MJX_PUSHT_ENV_GRAPH_MODE=WARP --backend mjx-warp $w $common > wide-2.log 2>&1 &
      wait
      scale "" 0.95 wide 4 $ppo_per MJX_PUSHT_ENV_GRAPH_MODE=WARP --backend mjx-warp $w $common > wide-4.log 2>&1
      }
      echo "$(date +%T) plan done"; exit 0
    fi
    if [ "$1" = ppo-procs ]; then
      # PPO on MJX-Warp as a process a GPU (`--num-processes`, Brax's pmap over every process's one GPU) against one
      # GPU, weak scaling, a fixed budget each (PPO over processes refuses --minutes and --until): ppo-apart's four
      # lone processes kept 3.75x one GPU's steps where one process over four made 2.8x. GPUS: the host's (2 or 4).
      # T: env steps a GPU (60 M: ~70 s of epochs at one H200's ~850k a second, lead19); ENVS: envs a GPU
      n=${GPUS:-$(nvidia-smi -L | wc -l)} t=${T:-60000000}
      e=${ENVS:-8192}  # envs a GPU: 8,192 made 1.71x on 2 H200s, 16,384 1.81x (lead29)
      w() { echo --algo ppo --backend mjx-warp --envs $((e * $1)) --batch $((e / 16 * $1)) --timesteps $((t * $1)) \
              --iterations 8 $common; }  # the run on N GPUs: N x one GPU's envs, minibatch and steps
      # shellcheck disable=SC2046  # the recipe: a list of flags
      scale 0 0.95 procs 1 "" "" $(w 1) > procs-1.log 2>&1
      for ((k = n - 1; k >= 0; k--)); do  # process 0 last: it listens at the coordinator, the others wait for it
        # shellcheck disable=SC2046  # the recipe: a list of flags
        run env CUDA_VISIBLE_DEVICES=$k python3 -m mjx_pusht train $(w "$n") --num-processes "$n" --process-id $k \
          --coordinator 127.0.0.1:${PORT:-29517} --out "procs/devices-$n" > "procs-$n-p$k.log" 2>&1 &
      done
      wait
      run python3 -m benchmarks.train_scaling --collect --devices "1,$n" --goal 0.95 --out procs > procs-collect.log 2>&1
      tail -n 6 procs-collect.log; echo "$(date +%T) plan done"; exit 0
    fi
    if [ "$1" = pair ]; then
      # One GPU against two of the same host, side by side in one plan (GPU_LIST: the two, default 0,1; the others
      # may train meanwhile): DAgger from pixels as one program over the two (weak scaling, to 90% or 5 minutes),
      # then PPO on MJX-Warp as a process a GPU (Brax's pmap over the processes, weak scaling, T env steps a GPU,
      # the whole budget: PPO over processes refuses --until; ENVS envs a GPU, default 8,192).
      IFS=, read -r g0 g1 <<< "${GPU_LIST:-0,1}"
      # shellcheck disable=SC2086  # the recipes: lists of flags
      {
      scale "$g0" 0.9 pair-px 1 $px_per "" --backend mjx-warp $px --seed 0 > pair-px-1.log 2>&1
      scale "$g0,$g1" 0.9 pair-px 2 $px_per "" --backend mjx-warp $px --seed 0 > pair-px-2.log 2>&1
      }
      t=${T:-60000000}
      e=${ENVS:-8192}  # envs a GPU: 8,192 made 1.71x on 2 H200s, 16,384 1.81x (lead29)
      w() { echo --algo ppo --backend mjx-warp --envs $((e * $1)) --batch $((e / 16 * $1)) --timesteps $((t * $1)) \
              --iterations 8 $common; }  # the run on N GPUs: N x one GPU's envs, minibatch and steps
      # shellcheck disable=SC2046  # the recipe: a list of flags
      scale "$g0" 0.95 pair-ppo 1 "" "" $(w 1) > pair-ppo-1.log 2>&1
      for k in 1 0; do  # process 0 last: it listens at the coordinator, the other waits for it
        # shellcheck disable=SC2046  # the recipe: a list of flags
        run env CUDA_VISIBLE_DEVICES=$([ $k = 0 ] && echo "$g0" || echo "$g1") timeout 420 python3 -m mjx_pusht train \
          $(w 2) --num-processes 2 --process-id $k --coordinator 127.0.0.1:${PORT:-29517} --out pair-ppo/devices-2 \
          > "pair-ppo-2-p$k.log" 2>&1 &
      done
      wait
      run python3 -m benchmarks.train_scaling --collect --devices 1,2 --goal 0.95 --out pair-ppo > pair-ppo-collect.log 2>&1
      tail -n 6 pair-px-2.log pair-ppo-collect.log; echo "$(date +%T) plan done"; exit 0
    fi
    if [ "$1" = ppo-apart ]; then
      # four one-GPU PPO runs at once, a process a GPU (seeds 0-3, MINUTES long, no --until): if each keeps one GPU's
      # rate alone, what caps 4 GPUs of one run is inside its process (Brax's pmap over Warp's FFI calls); if each
      # slows as the 4-GPU run did, it is the host's
      w="--algo ppo --envs 8192 --batch 512 --timesteps 400000000 --iterations 80 --minutes ${MINUTES:-1}"
      for k in 0 1 2 3; do
        # shellcheck disable=SC2086  # the recipe: a list of flags
        scale $k 0.95 "apart-$k" 1 "" MJX_PUSHT_ENV_GRAPH_MODE=WARP --backend mjx-warp $w $common --seed $k \
          > "apart-$k.log" 2>&1 &
      done
      wait; echo "$(date +%T) plan done"; exit 0
    fi
    # 1. the probes, 2 GPUs each (one GPU's share each), a hang ended by timeout
    # shellcheck disable=SC2086  # the recipes: lists of flags
    # shellcheck disable=SC2046  # the recipe: a list of flags
    (run env CUDA_VISIBLE_DEVICES=0,1 timeout 400 python3 -m mjx_pusht train $(over --backend mjx-warp $px --envs 2048 \
       --batch 2048 --image-batch 256 --first-fits 1 --fit-steps 200 --image-steps 100 --iterations 2 --eval-envs 1024 \
       --devices 2 --out probe-px) > probe-px.log 2>&1; echo "exit $?" >> probe-px.log) &
    probe_ppo() {  # probe_ppo GRAPH-MODE: 30 s of PPO on MJX-Warp, GPUs 2 and 3, in that graph mode
      # shellcheck disable=SC2086  # the recipe: a list of flags
      # shellcheck disable=SC2046  # the recipe: a list of flags
      run env CUDA_VISIBLE_DEVICES=2,3 MJX_PUSHT_ENV_GRAPH_MODE=$1 timeout 400 python3 -m mjx_pusht train \
        $(over --backend mjx-warp $ppo --envs 16384 --batch 1024 --timesteps 800000000 --minutes 0.5 --devices 2 \
        --out "probe-ppo-$1") > "probe-ppo-$1.log" 2>&1; echo "exit $?" >> "probe-ppo-$1.log"
    }
    probe_ppo WARP &
    wait
    grep -q "^exit 0" probe-ppo-WARP.log || probe_ppo NONE
    tail -n 3 probe-*.log
    px_ok=""; grep -q "^exit 0" probe-px.log && px_ok=1
    ppo_backend=mjx-jax ppo_env=""
    for mode in NONE WARP; do
      grep -qs "^exit 0" "probe-ppo-$mode.log" && ppo_backend=mjx-warp ppo_env=MJX_PUSHT_ENV_GRAPH_MODE=$mode
    done
    echo "pixels on several GPUs: $([ -n "$px_ok" ] && echo trained || echo failed); PPO on several GPUs: $ppo_backend $ppo_env"
    # shellcheck disable=SC2086  # the recipes: lists of flags
    {
    [ -n "$px_ok" ] && scale "" 0.9 px-s0 4 $px_per "" --backend mjx-warp $px --seed 0 > px-s0.log 2>&1
    scale "" 0.95 ppo-s0 4 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 0 > ppo-s0.log 2>&1
    [ -n "$px_ok" ] && scale "" 0.9 px-s1 4 $px_per "" --backend mjx-warp $px --seed 1 > px-s1.log 2>&1
    scale "" 0.95 ppo-s1 4 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 1 > ppo-s1.log 2>&1
    if [ -n "$px_ok" ]; then
      scale 0 0.9 px-s0 1 $px_per "" --backend mjx-warp $px --seed 0 > px-s0-1.log 2>&1 &
      scale 1,2 0.9 px-s0 2 $px_per "" --backend mjx-warp $px --seed 0 > px-s0-2.log 2>&1 &
    fi
    scale 3 0.95 ppo-s0 1 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 0 > ppo-s0-1.log 2>&1 &
    wait
    scale 0,1 0.95 ppo-s0 2 $ppo_per "$ppo_env" --backend $ppo_backend $ppo --seed 0 > ppo-s0-2.log 2>&1
    }
    echo "$(date +%T) plan done" ;;
  watch)
    # every 15 s until the plan ends or WAIT (570) passes: the plan's log, each run's logs, curves and summaries in
    # one tar (not the resume checkpoints' rings, the eval tables or recordings), and each finished run's policy
    out=${OUT:?watch copies into \$OUT}; t=0
    while :; do
      (cd "$runs" && tar czf "$out/devices.tgz" --exclude='*.msgpack' --exclude='*.f32' --exclude='*.parquet' \
        --exclude='*.rrd' --exclude='checkpoint*' ./*.log $(ls -d probe-* px-* ppo-* pair-* wide apart-? procs 2>/dev/null | grep -v '\.log$') 2>/dev/null)
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
  *) echo "usage: train_devices.sh start [plan|ppo-wide|ppo-apart|ppo-procs|pair]|watch (plans of training on a 4-GPU machine)" >&2; exit 2 ;;
esac
