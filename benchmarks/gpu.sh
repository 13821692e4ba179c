#!/usr/bin/env bash
# Measurements on a lent GPU machine (carrying the wheels to one that reaches no registry: docs/offline-gpu.md).
# Usage there: bash benchmarks/gpu.sh STAGE TIER   (logs and results go under $OUT)
set -uo pipefail
stage=$1; tier=${2:-h100}
export PYTHONPATH=$HOME/site:$PWD PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
export MJX_PUSHT_JAX_CACHE=$HOME/jax_cache
mkdir -p "$OUT/results"
# DAgger's recipe, one place for train-seeds and train-state: the network and its fits, and from state the episodes
# an iteration, the ring (notebook lead4) and the first fit from FIRST_FITS initialisations (4; 1: plain, lead6)
dagger_fit="--hidden 1024,1024,1024 --fit-steps 10000 --batch 4096 --beta-decay 0.7"
state_data="--envs ${ENVS:-16384} --max-samples ${MAX_SAMPLES:-32000000} --first-fits ${FIRST_FITS:-4}"
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
  expert-gym) # gym-pusht's task's expert on 4,096 held-out starts of the drop-in, MJX-Warp and MuJoCo C (this host's
          # cores); pair them here with `mjx-pusht compare --evals`
          for b in mjx-warp cpu; do
            python3 -m mjx_pusht eval --task gym-pusht --seeds 1000000000:1000004096 --backend $b --no-rerun --no-progress \
              --out "$OUT/expert-gym-$b" > "$OUT/expert-gym-$b.log" 2>&1
          done ;;
  task-study) python3 -m mjx_pusht.study.studies kv-expert --seeds 4096 --backend mjx-warp --out "$OUT/kv-expert" \
            > "$OUT/kv-expert.log" 2>&1
          python3 -m mjx_pusht compare --controller expert --reset task --seeds 4096 --backend mjx-warp \
            --out "$OUT/compare-task-mjx-warp" > "$OUT/compare-task.log" 2>&1 ;;
  render) python3 -m benchmarks.render --backend mjx-warp --tier "$tier" --batches "${BATCHES:-1024,4096,16384,65536}" \
            --save-pixels "$OUT/pixels-$tier.npz" --out "$OUT/results" > "$OUT/$stage.log" 2>&1
          python3 -m benchmarks.render --backend mjx-warp --tier "$tier" --vector-env --out "$OUT/results" >> "$OUT/$stage.log" 2>&1 ;;
  raster) # the pure-JAX renderer (render/raster.py, which runs under shard_map) against MJX-Warp's ray tracer on the same states:
          # images/s at the learner's 512 images a minibatch and up, and the pixels they differ in (no GL here: no cpu)
          python3 -m benchmarks.raster --renderers raster,warp --batches "${BATCHES:-512,4096,65536}" \
            --json "$OUT/results/$tier-raster.json" > "$OUT/$stage.log" 2>&1 ;;
  e2e-1m) # the 1 M-seed CLI as a user runs it: one warm-up, then 3 runs with the default audit and 3 with --audit 0
          python3 -m mjx_pusht sweep --seeds 65536 --backend mjx-warp --no-rerun --no-progress --out "$HOME/warm" \
            > "$OUT/e2e.log" 2>&1
          for mode in default audit0; do for i in 1 2 3; do
            extra=""; [ "$mode" = audit0 ] && extra="--audit 0"
            t0=$(date +%s%N)
            python3 -m mjx_pusht sweep --seeds 1000000 --backend mjx-warp --no-rerun --no-progress \
              --out "$HOME/e2e" $extra >> "$OUT/e2e.log" 2>&1
            t1=$(date +%s%N)
            echo "$mode $i $(( (t1 - t0) / 1000000 ))" | tee -a "$OUT/e2e-times.txt"
            python3 -c "import json,sys; d=json.load(open('$HOME/e2e/summary.json')); print(json.dumps({'mode': '$mode', 'run': $i, 'timing': d['timing'], 'audit': d.get('audit'), 'device': d['device'], 'versions': d['versions']}))" >> "$OUT/e2e-summaries.jsonl"
          done; done ;;
  two-process) # 2 GPUs: one process driving both (a thread a GPU) against two processes joined by jax.distributed
          export NCCL_NVLS_ENABLE=0 TORCH_SYMM_MEM_DISABLE_MULTICAST=1 NVSHMEM_DISABLE_NVLS=1
          python3 -m mjx_pusht sweep --seeds 131072 --backend mjx-warp --no-rerun --no-progress --audit 0 \
            --out "$HOME/warm" > "$OUT/two.log" 2>&1
          for i in ${RUNS:-1 2}; do
            rm -rf "$HOME/one" "$HOME/two"
            t0=$(date +%s%N)
            python3 -m mjx_pusht sweep --seeds 1000000 --backend mjx-warp --no-rerun --no-progress --audit 0 \
              --out "$HOME/one" >> "$OUT/two.log" 2>&1
            t1=$(date +%s%N)
            echo "one-process-two-threads $i $(( (t1 - t0) / 1000000 ))" | tee -a "$OUT/two-times.txt"
            cp "$HOME/one/summary.json" "$OUT/one-process-summary.json"
            port=$(( 23000 + i ))
            t0=$(date +%s%N)
            for p in 1 0; do
              CUDA_VISIBLE_DEVICES=$p python3 -m mjx_pusht sweep --seeds 1000000 --backend mjx-warp --no-rerun \
                --no-progress --audit 0 --out "$HOME/two" --num-processes 2 --process-id $p \
                --coordinator 127.0.0.1:$port >> "$OUT/two-p$p.log" 2>&1 &
            done
            wait
            t1=$(date +%s%N)
            echo "two-processes $i $(( (t1 - t0) / 1000000 ))" | tee -a "$OUT/two-times.txt"
            cp "$HOME/two/summary.json" "$OUT/two-process-summary.json"
          done
          python3 -c "
import pyarrow.parquet as pq, numpy as np
a = pq.read_table('$HOME/one/per_seed.parquet').to_pydict(); b = pq.read_table('$HOME/two/per_seed.parquet').to_pydict()
same = all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a)
rows = np.all([np.asarray(a[k]) == np.asarray(b[k]) for k in a if k.startswith('tee_')], axis=0)
print('tables identical:', same, 'rows identical:', rows.mean(), 'seeds equal:', a['seed'] == b['seed'],
      'rigid:', np.mean(a['tee_stayed_rigid']), np.mean(b['tee_stayed_rigid']))" | tee -a "$OUT/two-times.txt" ;;
  train-pixels) # DAgger from pixels for MINUTES (default 19.5) of training, started in its own process session
          # (setsid) so that it outlives this call (a call runs at most 10 minutes) and trains on without a
          # resume; `watch` calls, back to back, keep the machine held and copy back its log and results.
          # FIT_STEPS / IMAGE_STEPS: the actions' and the reader's steps an iteration (change 25 ran 4000 / 4000).
          # run from $HOME/runs with a relative --out, so the log copied back names no machine's path
          run=$HOME/runs/${RUN:-px}; mkdir -p "$HOME/runs"; cd "$HOME/runs"
          setsid nohup python3 -m mjx_pusht train --obs pixels_agent_pos --backend mjx-warp --reset task --envs 4096 \
            --iterations 300 --minutes "${MINUTES:-19.5}" --hidden 1024,1024,1024 \
            --fit-steps "${FIT_STEPS:-10000}" --image-steps "${IMAGE_STEPS:-4000}" --batch 4096 --image-batch 512 \
            --max-samples 8000000 --beta-decay 0.7 --eval-envs 4096 --seed "${SEED:-0}" --no-progress --no-rerun \
            --record 8 --keep "${KEEP:-best}" --out "${RUN:-px}" > "$run.log" 2>&1 < /dev/null &
          echo $! > "$run.pid"; sleep "${WAIT:-60}"; cp "$run.log" "$OUT/" ;;
  watch)  # wait up to WAIT seconds (default 570) for the run started by train-pixels, then copy back what it has
          run=$HOME/runs/${RUN:-px}; t=0
          while kill -0 "$(cat "$run.pid")" 2>/dev/null && [ "$t" -lt "${WAIT:-570}" ]; do sleep 5; t=$((t + 5)); done
          cp "$run.log" "$OUT/"; for f in curve.csv curve.png summary.json policy.msgpack; do
            [ -f "$run/$f" ] && cp "$run/$f" "$OUT/"; done
          [ -f "$run/eval/summary.json" ] && mkdir -p "$OUT/eval" && cp "$run/eval/summary.json" "$OUT/eval/"; true ;;
  train-ppo) # Brax PPO from state at change 18's settings for MINUTES (default 10) of training, with
          # --keep best (validation seeds) and the sampled action (ACT=mean for Brax's deterministic one), started
          # in its own session like train-pixels (about 11.5 minutes with compiling and eval); then
          # `watch` with the same RUN (default ppo-SEED) copies it back. The curve has both actions' held-out
          # success and Brax's losses per judgement (success_mean, success_sample, brax_*).
          run=$HOME/runs/${RUN:-ppo-${SEED:-0}}; mkdir -p "$HOME/runs"
          setsid nohup python3 -m mjx_pusht train --algo ppo --backend mjx-warp --reset task --envs 8192 --batch 512 \
            --timesteps 400000000 --iterations 80 --minutes "${MINUTES:-10}" --seed "${SEED:-0}" --keep "${KEEP:-best}" \
            --ppo-act "${ACT:-sample}" --no-progress --no-rerun --record 0 --out "$run" > "$run.log" 2>&1 < /dev/null &
          echo $! > "$run.pid"; sleep "${WAIT:-60}"; cp "$run.log" "$OUT/" ;;
  train-seeds) # RECIPE (ppo, dagger-state or dagger-pixels) on SEEDS (comma-separated) one after another, as one
          # result (benchmarks/train_seeds.py: each run, then seeds.json/.md with mean, sd, min); started in its own
          # session like train-pixels, then `watch-seeds`. A machine is held at most 30 minutes, so give each hold
          # what fits: ppo 2 seeds (~11.5 min each), dagger-state 4 (~5.7), dagger-pixels 1 (~22); aggregate the
          # holds' copied-back runs here with `python -m benchmarks.train_seeds --collect DIR... --out DIR`.
          # EXTRA: more train flags as they are (e.g. "--goal random", "--randomize kp=0.5:2,kv=0.5:2").
          # ACTION_EPS (DAgger): --action-eps, the actions' loss relative to each label's size above it (m/s).
          # LATE_FITS (DAgger): --late-fits, fits an iteration once the expert's share is at most 1%.
          # FIRST_FITS (DAgger): --first-fits, initialisations of the first fit, the lowest loss kept (notebook lead5;
          # 4 by default: dagger-state since notebook lead6, dagger-pixels since lead13 (2 of 2 seeds at 90%, where one
          # initialisation left seed 0 at 81%, lead12); 1 is the plain fit).
          # ITERATIONS (DAgger; state 60, pixels 300 by default): a cap beside the minutes, so a faster card (H200) does
          # no more iterations than an H100 does in its minutes (state: 33-35 in 5 minutes since the host-work fixes,
          # notebook lead8, 24-27 before them; pixels: 52 in 19.7 minutes before them, change 27).
          # ENVS, MAX_SAMPLES (DAgger): episodes an iteration and the ring (state: 16384 and 32000000, notebook lead4;
          # pixels: 4096 and 8000000 on the chapter's task, as change 27 measured; 16384 and 32000000 on gym-pusht's).
          # MAX_GRAD_NORM, LR_SCHEDULE (PPO): --max-grad-norm (default 1.0; off: unclipped), --lr-schedule (adaptive-kl).
          # GPU: the one GPU of a several-GPU machine this run takes (CUDA_VISIBLE_DEVICES), so that each GPU runs
          # its own seeds at one GPU's speed; NAME (default RECIPE) names the run's folder, one a concurrent run.
          run=$HOME/runs/seeds-${NAME:-${RECIPE:?RECIPE=ppo, dagger-state or dagger-pixels}}; mkdir -p "$run"
          dagger="$dagger_fit ${LATE_FITS:+--late-fits $LATE_FITS} ${ACTION_EPS:+--action-eps $ACTION_EPS}"
          # TASK (default chapter, from its task starts): gym-pusht trains on gym-pusht's task; MINUTES: dagger-state's
          task="--reset task"; [ -n "${TASK:-}" ] && task="--task $TASK"
          # pixels: 4,096 episodes an iteration and an 8 M ring on the chapter's task (change 27); on gym-pusht's the
          # state recipe's 16,384 and 32 M, train's own defaults there (97.5%, 97.9% on seeds 0, 1; 96-97% at 4,096)
          px_envs=4096 px_samples=8000000; [ "${TASK:-}" = gym-pusht ] && px_envs=16384 px_samples=32000000
          task="$task ${EXTRA:-}"
          case "$RECIPE" in
            ppo) args="--algo ppo --envs 8192 --batch 512 --timesteps 400000000 --iterations 80 --minutes 10 \
              ${MAX_GRAD_NORM:+--max-grad-norm $MAX_GRAD_NORM} ${LR_SCHEDULE:+--lr-schedule $LR_SCHEDULE}" ;;
            dagger-state) args="$dagger --iterations ${ITERATIONS:-60} --minutes ${MINUTES:-5} $state_data" ;;
            dagger-pixels) args="$dagger --first-fits ${FIRST_FITS:-4} --obs pixels_agent_pos --iterations ${ITERATIONS:-300} --minutes ${MINUTES:-19.5} --image-steps 4000 \
              --image-batch 512 --envs ${ENVS:-$px_envs} --max-samples ${MAX_SAMPLES:-$px_samples}" ;;
            *) echo "unknown RECIPE $RECIPE" >&2; exit 2 ;;
          esac
          # shellcheck disable=SC2086  # $args is a list of flags
          # run from $HOME/runs with a relative --out, so the logs copied back name no machine's path; the pid file is
          # written from inside the new session (setsid forks where the caller leads a process group, and the pid
          # of `$!` is then gone at once)
          (cd "$HOME/runs" && ${GPU:+env CUDA_VISIBLE_DEVICES=$GPU} setsid nohup bash -c 'echo $$ > "$0"; exec "$@"' \
            "$run.pid" python3 -m benchmarks.train_seeds --seeds "${SEEDS:?SEEDS=0,1,...}" --out "$(basename "$run")" \
            --goal "${GOAL:-0.9}" -- --backend mjx-warp $task $args --keep best --no-progress --no-rerun \
            --record 0 > "$run.log" 2>&1 < /dev/null &)
          sleep "${WAIT:-60}"; cp "$run.log" "$OUT/" ;;
  train-scaling) # one run each on DEVICES (default 1,2,4) GPUs of this host, the same run otherwise (
          # benchmarks/train_scaling.py: control steps/s during training, x one GPU, and minutes to GOAL held-out, in
          # scaling.json/.md): RECIPE ppo (Brax PPO from state, 3 minutes) or dagger-state (DAgger from state, 5
          # minutes). PPO on 2 and 4 H200s segfaulted in XLA's compile of Brax's pmap (jax 0.11.2, notebook lead12):
          # try dagger-state first, and PPO with the pinned jax carried (notebook lead12). Started in its
          # own session like train-seeds (about 5-7 minutes a run with compiling and eval), then
          # `watch-seeds NAMES=scaling-RECIPE` copies back the runs and scaling.json.
          run=$HOME/runs/seeds-scaling-${RECIPE:?RECIPE=ppo or dagger-state}; mkdir -p "$run"
          case "$RECIPE" in
            # PPO over several GPUs on mjx-warp fails in its CUDA-graph FFI call, Warp or XLA capturing it (pinned jax,
            # notebooks lead13, lead15): mjx-jax, or BACKEND=mjx-warp with MJX_PUSHT_ENV_GRAPH_MODE=WARP or NONE (not
            # measured; the staged default shares one graph between devices).
            # The whole 4-GPU plan of training on several GPUs, weak scaling, is tools/offline-gpu/train_devices.sh
            ppo) args="--algo ppo --envs 8192 --batch 512 --timesteps 400000000 --iterations 80 --minutes ${MINUTES:-3}"
                 backend=${BACKEND:-mjx-jax} ;;
            dagger-state) args="$dagger_fit --iterations ${ITERATIONS:-60} --minutes ${MINUTES:-5} $state_data"
                 backend=${BACKEND:-mjx-warp} ;;
            *) echo "unknown RECIPE $RECIPE" >&2; exit 2 ;;
          esac
          # shellcheck disable=SC2086  # $args is a list of flags
          (cd "$HOME/runs" && setsid nohup bash -c 'echo $$ > "$0"; exec "$@"' "$run.pid" python3 -m benchmarks.train_scaling \
            --devices "${DEVICES:-1,2,4}" --goal "${GOAL:-0.95}" --out "$(basename "$run")" -- --backend "$backend" \
            --reset task $args --seed "${SEED:-0}" --keep best --no-progress --no-rerun --record 0 > "$run.log" 2>&1 < /dev/null &)
          sleep "${WAIT:-60}"; cp "$run.log" "$OUT/" ;;
  goals-and-gains) # random goals and drawn gains in one hold, one after another in the background (watch with watch-seeds NAMES="goals rand"):
          # DAgger from state on gym-pusht's task with a goal per episode, then with kp and kv drawn per episode (10
          # minutes each, seed 0), then the env loop's steps/s with goals and drawn physics beside the fixed ones
          cat > "$HOME/goals-and-gains.sh" <<EOS
cd "$PWD"
TASK=gym-pusht MINUTES=10 RECIPE=dagger-state SEEDS=0 NAME=goals EXTRA="--goal random" WAIT=1 bash benchmarks/gpu.sh train-seeds $tier
while kill -0 \$(cat $HOME/runs/seeds-goals.pid) 2>/dev/null; do sleep 5; done
TASK=gym-pusht MINUTES=10 RECIPE=dagger-state SEEDS=0 NAME=rand EXTRA="--randomize kp=0.5:2,kv=0.5:2" WAIT=1 bash benchmarks/gpu.sh train-seeds $tier
while kill -0 \$(cat $HOME/runs/seeds-rand.pid) 2>/dev/null; do sleep 5; done
python3 -m benchmarks.env_loop --envs 16384,65536 --cases scan_autoreset,scan_autoreset_randomized,scan_autoreset_goals,scan_autoreset_goals_randomized --json $HOME/runs/$tier-env-loop-goals-randomized.json > $HOME/runs/env-loop.log 2>&1
EOS
          setsid nohup bash "$HOME/goals-and-gains.sh" > "$HOME/goals-and-gains.log" 2>&1 < /dev/null &
          sleep 30; cp "$HOME/goals-and-gains.log" "$OUT/" ;;
  goals-randomized-pixels) # the throughput with pixels, goals and drawn physics: the env loop's steps/s with goals (the target drawn at each)
          # and drawn physics beside the fixed ones, 96 x 96 images rendered in every step (one call, foreground)
          python3 -m benchmarks.env_loop --envs 16384,65536 --obs pixels --cases scan_autoreset,scan_autoreset_randomized,scan_autoreset_goals,scan_autoreset_goals_randomized \
            --json "$OUT/results/$tier-env-loop-goals-randomized-pixels.json" > "$OUT/$stage.log" 2>&1 ;;
  gym-pusht-x4) # gym-pusht's task's pixel and PPO runs in one hold of 4 GPUs, a GPU each, in the background (watch-seeds, back to back:
          # NAMES="ppo-gym-0 ppo-gym-1 bench" first, then NAMES="px-gym-0 px-gym-1"): GPUs 0 and 1 DAgger from pixels on
          # gym-pusht's task, seeds 0 and 1, MINUTES (default 16) each; GPUs 2 and 3 PPO from state on it, seeds 0 and 1
          # (10 minutes); then on GPU 2 the pixel env loop (goals, drawn physics) and on GPU 3 the raster
          # renderer against MJX-Warp's, as run "bench" (its results under seeds-bench/results)
          for s in 0 1; do
            TASK=gym-pusht RECIPE=dagger-pixels SEEDS=$s NAME=px-gym-$s GPU=$s MINUTES=${MINUTES:-16} WAIT=0 bash benchmarks/gpu.sh train-seeds $tier
            TASK=gym-pusht RECIPE=ppo SEEDS=$s NAME=ppo-gym-$s GPU=$((s + 2)) WAIT=0 bash benchmarks/gpu.sh train-seeds $tier
          done
          mkdir -p "$HOME/runs/seeds-bench"; cat > "$HOME/bench.sh" <<EOS
cd "$PWD"; sleep 5
for s in 0 1; do while kill -0 \$(cat $HOME/runs/seeds-ppo-gym-\$s.pid) 2>/dev/null; do sleep 5; done; done
OUT=$HOME/runs/seeds-bench CUDA_VISIBLE_DEVICES=2 bash benchmarks/gpu.sh goals-randomized-pixels $tier &
OUT=$HOME/runs/seeds-bench CUDA_VISIBLE_DEVICES=3 bash benchmarks/gpu.sh raster $tier
wait
EOS
          (cd "$HOME/runs" && setsid nohup bash -c 'echo $$ > "$0"; exec "$@"' "$HOME/runs/seeds-bench.pid" \
            bash "$HOME/bench.sh" > "$HOME/runs/seeds-bench.log" 2>&1 < /dev/null &)
          sleep "${WAIT:-60}"; cp "$HOME"/runs/seeds-*.log "$OUT/"; nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1; true ;;
  diffusion-hold) # LeRobot's Diffusion Policy whole in one hold of a 4-GPU host (nvidia-h100-x4: 64 cores), since nothing off git outlives a
          # session (session 16's checkpoint did not): LeRobot's training is bound by its loader, ~93 samples a second a
          # worker (notebook lead16), so the 2,000 episodes train on GPU 0 with WORKERS_BIG (46) workers at a batch of
          # 256 (the update's 0.055 s on the GPU then meets the loader); the 200 episodes on GPU 1 at the same settings
          # with 14 (fewer updates in the same minutes: the sizes compare at the curve's points, equal updates); Warp's
          # kernels compile meanwhile on GPU 3 for the curve's evals. STEPS 10,000: the ~10.7 updates a second measured
          # (session 17: 12,000 did not fit, the run stopped for the final evals mid-save of step 10,000) end the schedule inside the hold,
          # a checkpoint every 1,000 so a stop loses little. Then: `diffusion_pusht.sh wait` calls with
          # SIZES="200 2000", `eval-final-2000` with EVAL_GPUS="2 3", `wait bundle`.
          # SMALL=0: the 2,000 alone (WORKERS_BIG=60: 11.3 updates a second, session 18, where the update itself,
          # not the loader, was then the wait). FROM=~/diffusion/NAME/pretrained_model (bundled in .gpu-demos/NAME):
          # the run starts from that policy's weights with a new optimizer and schedule (diffusion_pusht.sh FROM).
          # The sizes at equal updates: the loader split evenly, WORKERS_BIG=WORKERS_SMALL= half the cores less one
          # (30 on a 4-GPU host, 15 on nvidia-h100-x2's 32 cores). SIZE0=200 SMALL=0: the 200 episodes alone on GPU 0
          # (the sizes at equal updates in holds of their own: STEPS=12000 STOP_AT=8000 is hold 1's schedule, cut where
          # hold 1's 2,000-episode run was, so the two compare at 8,000 updates)
          dp() { env OUT="$OUT" BATCH="${BATCH:-256}" LR="${LR:-2e-4}" STEPS="${STEPS:-10000}" SAVE_FREQ="${SAVE_FREQ:-1000}" \
                   EVAL_FREQ="${EVAL_FREQ:-3000}" SCHED=DDIM INFER_STEPS=10 "$@"; }
          [ -n "${FROM:-}${STOP_AT:-}" ] && [ "${SMALL:-1}" = 1 ] && {  # dp passes them to both sizes' runs
            echo "diffusion-hold: FROM and STOP_AT are for the run on GPU 0 alone; give SMALL=0 with them" >&2; exit 2; }
          [ "${SIZE0:-2000}" != 200 ] || [ "${SMALL:-1}" = 0 ] || {
            echo "diffusion-hold: SIZE0=200 trains the 200 episodes on GPU 0; give SMALL=0 with it" >&2; exit 2; }
          # a setting diffusion_pusht.sh refuses (its one line, exit 2) ends the stage there, before any GPU work
          CUDA_VISIBLE_DEVICES=0 dp SIZES="${SIZE0:-2000}" WORKERS="${WORKERS_BIG:-46}" bash benchmarks/diffusion_pusht.sh "train-${SIZE0:-2000}" || exit
          if [ "${SMALL:-1}" = 1 ]; then
            CUDA_VISIBLE_DEVICES=1 dp SIZES=200 WORKERS="${WORKERS_SMALL:-14}" bash benchmarks/diffusion_pusht.sh train-200 || exit; fi
          # the last GPU (3 on a 4-GPU host, 1 on a 2-GPU one, where it shares with the 200 episodes' run)
          CUDA_VISIBLE_DEVICES=$(( $(nvidia-smi -L | wc -l) - 1 )) python3 -m mjx_pusht demos --task gym-pusht --seeds 0:4 --replace --out "$HOME/warm" \
            --no-progress > "$OUT/warm.log" 2>&1; tail -n 2 "$OUT/warm.log"
          sleep "${WAIT:-30}"; nproc; nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1
          for l in "$HOME"/diffusion/logs/train-*.log; do echo "== $l"; grep -a "updt_s" "$l" | tail -n 3 | cut -c1-240; done
          true ;;
  diffusion-and-pixels) # one H100 hold for two studies at once, each run in the background: LeRobot's Diffusion Policy
          # (benchmarks/diffusion_pusht.sh: the expert's 200 and 2,000 demos, the update rate, then both sizes' training
          # side by side for DP_MINUTES, default 12, of updates) and DAgger from pixels on gym-pusht's task, seeds 0 and 1
          # side by side, FIRST_FITS 4, MINUTES (default 18) each. They share the one GPU: LeRobot's training is bound by
          # its dataloaders (2% of the GPU, 8 updates/s side by side, notebook lead13), so every figure of either is a
          # lower bound on what it does alone. Then: `diffusion_pusht.sh wait` calls, `eval-final-200 eval-final-2000`,
          # `watch-seeds NAMES="px-gym-0 px-gym-1"` and `diffusion_pusht.sh wait bundle` (the 8 files a call returns).
          dp() { env OUT="$OUT" SIZES="200 2000" MINUTES="${DP_MINUTES:-12}" RATE_STEPS=300 POINTS=4 STEPS=rated \
                   bash benchmarks/diffusion_pusht.sh "$@"; }
          dp demos-200 demos-2000  # first, alone: Warp compiles its kernels once, into the cache the others read
          for s in 0 1; do
            TASK=gym-pusht RECIPE=dagger-pixels SEEDS=$s NAME=px-gym-$s MINUTES=${MINUTES:-18} WAIT=0 \
              bash benchmarks/gpu.sh train-seeds $tier
          done
          dp rate && dp train-200 train-2000
          sleep 30; nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1; tail -n 2 "$HOME"/runs/seeds-px-gym-*.log; true ;;
  watch-seeds) # wait up to WAIT seconds (default 570) for train-seeds' runs NAMES (default RECIPE; space-separated),
          # then copy back what they have: one tar a run (logs, curves, summaries; not the resume checkpoints' dataset
          # rings, 2.2 GB a state run, which made the tar too big to come back) and each finished seed's policy
          # (8.5 MB for DAgger's 1024 x 3) as NAME-seed-S.msgpack, once (a call brings back at most 8 files of 16 MB)
          names=${NAMES:-${RECIPE:?RECIPE or NAMES as given to train-seeds}}; t=0
          for n in $names; do run=$HOME/runs/seeds-$n
            while kill -0 "$(cat "$run.pid")" 2>/dev/null && [ "$t" -lt "${WAIT:-570}" ]; do sleep 5; t=$((t + 5)); done
          done
          for n in $names; do run=$HOME/runs/seeds-$n
            (cd "$HOME/runs" && tar czf "$OUT/$n.tgz" --exclude='*.msgpack' --exclude='*.f32' --exclude='*.parquet' --exclude='*.rrd' \
              "seeds-$n.log" "seeds-$n")
            for d in "$run"/seed-*; do [ -f "$d/eval/summary.json" ] && [ ! -f "$d/sent" ] && [ "${POLICIES:-1}" = 1 ] && \
              cp "$d/policy.msgpack" "$OUT/$n-$(basename "$d").msgpack" && touch "$d/sent"; done
          done; tail -n 3 "$HOME"/runs/seeds-*.log; true ;;
  train-state) # DAgger from state for MINUTES (default 5) of training, inside one call (about 6.5 minutes with
          # compiling and the held-out eval); results and the held-out eval's table are copied back. ENVS, MAX_SAMPLES
          # as train-seeds' (16384 episodes an iteration and a 32 M ring; before notebook lead4: 4096 and 8 M)
          run=$HOME/runs/state-${SEED:-0}; mkdir -p "$HOME/runs"
          # shellcheck disable=SC2086  # the recipe's strings are lists of flags
          (cd "$HOME/runs" && python3 -m mjx_pusht train --backend mjx-warp --reset task --iterations "${ITERATIONS:-60}" \
            --minutes "${MINUTES:-5}" $dagger_fit $state_data --seed "${SEED:-0}" --keep "${KEEP:-best}" --no-progress --no-rerun --record 0 --out "state-${SEED:-0}") > "$OUT/$stage.log" 2>&1
          for f in curve.csv curve.png summary.json policy.msgpack; do [ -f "$run/$f" ] && cp "$run/$f" "$OUT/"; done
          mkdir -p "$OUT/eval"; cp "$run"/eval/*.parquet "$run"/eval/summary.json "$OUT/eval/" 2>/dev/null; true ;;
  transfer) # a trained policy (POLICY=path) on the 4,096 held-out task seeds, on MJX-Warp and on MuJoCo C, paired
          # seed by seed; a pixel policy renders on the CPU too, so EGL must be there (.gl, see the device README)
          MUJOCO_GL=egl python3 -m mjx_pusht compare --controller "policy:${POLICY:?POLICY=path of a policy.msgpack}" \
            --backend mjx-warp --seeds 1000000000:1000004096 --reset task --out "$OUT/transfer-mjx-warp" \
            > "$OUT/$stage.log" 2>&1 ;;
  host-work) # DAgger's work between its device programs (benchmarks/dagger_host_work.py, notebook lead7): a rollout's
          # samples into the ring, compiled programs and seconds an iteration, and the resume checkpoint of a 32 M ring
          python3 -m benchmarks.dagger_host_work --envs 16384 --samples 32000000 --ring-samples 32000000 \
            --json "$OUT/results/$tier-dagger-host-work.json" > "$OUT/$stage.log" 2>&1 ;;
  finite-check) # the MJX-Warp rollout at 65,536 seeds with the finiteness check of the actions and without it, in turns
          python3 -m benchmarks.finite_check --backend mjx-warp --batch 65536 --repeats "${REPEATS:-5}" \
            --out "$OUT/results/$tier-finite-check.json" > "$OUT/$stage.log" 2>&1 ;;
  dropin-fidelity) # the drop-in's MJX-Warp batch against gym-pusht itself (needs gym-pusht 0.1.8, pymunk, pygame,
            # shapely, opencv in the site); SOURCES=scripted,walk,expert EPISODES=1000 by default scripted only
            python3 -m benchmarks.dropin_fidelity --backend mjx-warp --sources "${SOURCES:-scripted}" \
            --episodes "${EPISODES:-1000}" --workers "${WORKERS:-14}" --closed-loop \
            --json "$OUT/results/$tier-dropin-fidelity.json" > "$OUT/$stage.log" 2>&1 ;;
  *) echo "unknown stage $stage" >&2; exit 2 ;;
esac
