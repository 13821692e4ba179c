#!/usr/bin/env bash
# LeRobot 0.6.1's own Diffusion Policy (`lerobot-train --policy.type=diffusion`, unchanged) trained on `mjx-pusht
# demos` of the gym-pusht expert on one lent H100, evaluated on the plugin's batch as it trains, then scored by
# `lerobot-eval` on gym-pusht itself and on the batch (docs/lerobot-diffusion.md has the plan).
# Usage there, from the repository root, with lerobot 0.6.1 (and diffusers), gym-pusht, this project and its plugin
# installed (docs/offline-gpu.md: tools/offline-gpu/ carries the wheels to $HOME/site):
#   bash benchmarks/diffusion_pusht.sh STAGE [STAGE ...]        # stages run in the order given
# A command lasts at most 10 minutes but a machine is held up to 30: training and the final evals run detached
# (setsid, so they outlive the call that started them) and `wait` collects them; a bare new machine (a new hold)
# loses all of $RUNS, so a run that must go on leaves as parts (`pack`) and comes back carried (`unpack`).
# A machine idle for 30 s between calls is given back, its detached jobs with it: call again at once.
#
# Stages (device calls each, on a machine already set up):
#   demos-N      the expert's N episodes from seeds 10000.. (clear of lerobot-eval's 1000..1499), successful ones
#                kept, in $RUNS/demos-N; a line in $OUT/results/diffusion-demos.jsonl. Seconds (+ ~2 min of Warp's
#                first compile on a fresh machine); run with the stage after it, no call of its own.
#   rate         the SIZES' training side by side for RATE_STEPS updates, no evals: the update rate, and so STEPS,
#                EVAL_FREQ and SAVE_FREQ for MINUTES of training ($OUT/results/diffusion-rate.json). ~2 min, with demos.
#   train-N      starts (or, when $RUNS/train-N has a checkpoint, resumes with LeRobot's --resume) lerobot-train on
#                demos-N, detached; returns at once. Run every size in one call, then `wait`. STOP_AT=K: the run
#                ends once its step-K checkpoint is saved, its schedule still STEPS long (a schedule cut short, as
#                an earlier run was, to compare with it at equal updates).
#   eval-final-N detached: lerobot-eval of train-N's last checkpoint, 500 episodes on --env.type=mjx_pusht (one batch
#                of 500) then on --env.type=pusht (gym-pusht, LeRobot's SyncVectorEnv), one after the other on the same
#                machine; each a row (wall-clock, Wilson 95% interval) in $OUT/results/diffusion-eval-N.json.
#                EVAL_GPUS="G1 G2" (a host of several GPUs): the two at once, the batch on G1, gym-pusht on G2.
#   wait         waits until the detached jobs end or WAIT_MIN minutes (default 9) pass, then returns the logs
#                ($OUT/logs.tgz), the curve ($OUT/diffusion-curve.json, .png) and the results: one call per 9 minutes.
#   pack-N       (stopping a train-N still running) train-N's last checkpoint (model, optimizer, scheduler, RNG: LeRobot's whole resume state) and its
#                logs as 15 MiB parts in $RUNS/pack; then `send` returns 4 of them a call (60 MiB
#                of the 64 that come back). PACK=model: the policy's pretrained_model folder alone (8 parts).
#                PACK=live: the training goes on; the checkpoint `last` names now is packed (LeRobot points `last`
#                at a step only once its folder is written), so its parts can leave the machine during the wait
#                calls: a hold lost mid-run (it goes back after 30 s without a call) then loses only the updates
#                since that checkpoint, and the hold's end needs no stop-pack-send of its own.
#   unpack-N     puts back a run carried in .gpu-diffusion/ (see below) as $RUNS/train-N with its logs.
# Carrying a packed run into a new hold: here, copy each call's parts (files_at/parts/*) into .gpu-diffusion/K/
# folders of at most 3 parts (45 MiB: a call carries 64 with the tree, ~3 MiB with outputs/ moved aside), and run
#   mkdir -p $HOME/carried && cp .gpu-diffusion/K/* $HOME/carried/       # carry [".gpu-diffusion/K"], one call each
# then `bash benchmarks/diffusion_pusht.sh unpack-N train-N wait` in the last one (once, here:
# echo /.gpu-diffusion/ >> "$(git rev-parse --git-path info/exclude)", so the parts never travel uncarried).
set -uo pipefail
export PYTHONPATH=$HOME/site:$PWD PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
export HF_HUB_OFFLINE=1 WANDB_MODE=disabled
export MJX_PUSHT_JAX_CACHE=${MJX_PUSHT_JAX_CACHE:-$HOME/jax_cache}
OUT=${OUT:-outputs/bench-diffusion}
RUNS=${RUNS:-$HOME/diffusion}  # the machine's disk: demos, runs, logs (gone with the hold)
PY=${PY:-python3}
SIZES=${SIZES:-200 2000}
STEPS=${STEPS:-30000}            # the whole run's updates (the cosine schedule's length): size it with `rate`, or
                                 # `rated`: each size's STEPS, EVAL_FREQ and SAVE_FREQ from the `rate` stage's JSON
MINUTES=${MINUTES:-10}           # the training minutes `rate` sizes STEPS for (a hold's 30 take setup and evals too)
RATE_STEPS=${RATE_STEPS:-400}
SAVE_FREQ=${SAVE_FREQ:-2000}     # updates between checkpoints: size with `rate` so a hold's end loses a minute or two
EVAL_FREQ=${EVAL_FREQ:-3000}     # the curve's points
POINTS=${POINTS:-5}              # the curve's points `rate` sizes EVAL_FREQ for
EVAL_EPISODES=${EVAL_EPISODES:-50}
DOWN_DIMS=${DOWN_DIMS:-128,256,512}  # 28.5 M parameters, a 326 MiB resume state; LeRobot's pusht run: 512,1024,2048
                                     # (263 M, 3 GiB: no hold could carry it on)
# dataloader workers a run: 14 of the 16 cores shared by the SIZES run side by side. LeRobot's training is bound by
# its loader below that: 6 workers a run waited 0.071-0.084 s for each batch; 14 alone, 0.003-0.009 s (notebook lead14)
WORKERS=${WORKERS:-$(( 14 / $(wc -w <<< "$SIZES") ))}
DEVICE=${DEVICE:-cuda}           # cpu: a smoke run of the stages on a machine without a GPU
BATCH=${BATCH:-64}
LR=${LR:-}                       # LeRobot's optimizer_lr (its default 1e-4, for a batch of 64): set it with BATCH
# the sampler the policy acts with (training is the same for both: the noise schedule's add_noise). LeRobot's run:
# DDPM's 100 steps, 100 denoisings a chunk of 8 actions, which alone kept 500 batch episodes above 60 s (lead13)
SCHED=${SCHED:-DDPM}
INFER_STEPS=${INFER_STEPS:-}     # num_inference_steps (unset: num_train_timesteps, 100)
WAIT_MIN=${WAIT_MIN:-9}
EVAL_GPUS=${EVAL_GPUS:-}         # eval-final-N on a host of several GPUs: "G1 G2", the batch's GPU and gym-pusht's,
                                 # both at once (unset: one after the other on the GPU the call sees)
CARRIED=${CARRIED:-$HOME/carried}  # where the carried parts of a packed run are gathered
# a pretrained_model folder (a checkpoint's weights, config and normalizers, not its optimizer): train-N starts from
# it with LeRobot's --policy.path, a new optimizer and schedule (STEPS, LR). For a run whose whole resume state did
# not survive the hold it came from (the optimizer's 2 x 114 MB): --resume is the way when it did
FROM=${FROM:-}
STOP_AT=${STOP_AT:-}             # train-N ends after saving this step's checkpoint (unset: at STEPS)
[ -z "$FROM" ] || [ -f "$FROM/config.json" ] || { echo "FROM must be a pretrained_model folder (with config.json), got '$FROM'" >&2; exit 2; }
# found here in one line, not in a detached training's log minutes later
case "$SCHED" in DDPM|DDIM) ;; *) echo "SCHED must be DDPM or DDIM (LeRobot's samplers), got '$SCHED'" >&2; exit 2 ;; esac
case "${PACK:-resume}" in resume|model|live) ;; *) echo "PACK must be resume, model or live, got '$PACK'" >&2; exit 2 ;; esac
whole() {  # NAME VALUE: a one-line error unless VALUE is a whole number above 0 (or empty, where $3 is "optional")
  [[ ( -z "$2" && "${3:-}" = optional ) || "$2" =~ ^[1-9][0-9]*$ ]] || {
    echo "$1 must be a whole number above 0, got '$2'" >&2; exit 2; }
}
whole INFER_STEPS "$INFER_STEPS" optional
whole STOP_AT "$STOP_AT" optional
for v in BATCH SAVE_FREQ EVAL_FREQ EVAL_EPISODES RATE_STEPS WAIT_MIN; do whole "$v" "${!v}"; done
[ "$STEPS" = rated ] || whole STEPS "$STEPS"
[[ "$EVAL_GPUS" =~ ^([0-9]+( [0-9]+)?)?$ ]] || { echo "EVAL_GPUS must be one or two GPU numbers (e.g. \"2 3\"), got '$EVAL_GPUS'" >&2; exit 2; }
[[ "$WORKERS" =~ ^[0-9]+$ ]] || { echo "WORKERS must be a whole number (0: load in the training process), got '$WORKERS'" >&2; exit 2; }
[[ -z "$LR" || "$LR" =~ ^[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?$ ]] || { echo "LR must be a number (e.g. 1e-4), got '$LR'" >&2; exit 2; }
mkdir -p "$OUT/results" "$RUNS/logs" "$RUNS/pids" "$RUNS/results"

# LeRobot's published diffusion_pusht settings (lerobot/diffusion_pusht's config) where they are not 0.6.1's
# defaults (which are horizon 64, 32 action steps and an ImageNet backbone fetched from the network), on the
# features of LeRobot's lerobot/pusht (observation.image 96 x 96, observation.state, action): what differs from
# that run is DOWN_DIMS, the demos and the budget (docs/lerobot-diffusion.md).
policy_args() {  # FROM set: LeRobot's own fine-tuning (--policy.path) from that policy's weights, the same settings
  local policy=--policy.type=diffusion; [ -z "$FROM" ] || policy=--policy.path=$FROM
  echo "$policy" --policy.device="$DEVICE" --policy.push_to_hub=false --policy.use_amp=false \
    --policy.n_obs_steps=2 --policy.horizon=16 --policy.n_action_steps=8 --policy.drop_n_last_frames=7 \
    --policy.crop_shape=[84,84] --policy.crop_is_random=true --policy.pretrained_backbone_weights=null \
    --policy.use_group_norm=true --policy.spatial_softmax_num_keypoints=32 "--policy.down_dims=[$DOWN_DIMS]" \
    --policy.num_train_timesteps=100 --policy.noise_scheduler_type="$SCHED" \
    ${INFER_STEPS:+--policy.num_inference_steps=$INFER_STEPS} --batch_size="$BATCH" --seed=100000 \
    ${LR:+--policy.optimizer_lr=$LR} \
    --num_workers="$WORKERS" --log_freq=100 --wandb.enable=false
}
# the curve's evals: the plugin's batch (the GPU's), seeds 100000.. (train's --seed), clear of the final eval's
env_args() {
  echo --env.type=mjx_pusht --env.observation_height=96 --env.observation_width=96 --env_eval_freq="$EVAL_FREQ" \
    --eval.n_episodes="$EVAL_EPISODES" --eval.batch_size="$EVAL_EPISODES" --eval.use_async_envs=false
}

trainer() {  # lerobot-train's module, or (STOP_AT) LeRobot's own run ended after that step's checkpoint
  if [ -z "$STOP_AT" ]; then echo lerobot.scripts.lerobot_train; else echo benchmarks.lerobot_train_until "$STOP_AT"; fi
}
stop_at() {  # STEPS SAVE_FREQ [FROM_STEP]: STOP_AT must name a checkpoint the run has yet to write before its end
  # (or it would never stop): after FROM_STEP, where a resumed run starts
  if [ -n "$STOP_AT" ] && { [ "$STOP_AT" -ge "$1" ] || [ $((STOP_AT % $2)) != 0 ]; }; then
    echo "STOP_AT must be a checkpoint's step before the run's end (a multiple of SAVE_FREQ $2 below STEPS $1), got $STOP_AT" >&2
    exit 2; fi
  if [ -n "$STOP_AT" ] && [ "$STOP_AT" -le "${3:-0}" ]; then
    echo "STOP_AT $STOP_AT is not ahead of the checkpoint train-$n resumes from (step $3)" >&2; exit 2; fi
}

detach() {  # NAME CMD...: CMD in a session of its own, its output in $RUNS/logs/NAME-<time>.log. The pid file is
  # written from inside the new session: where the caller leads a process group (a shell with job control, as the
  # device's runner is), setsid forks, `$!` names a process gone at once, and `wait` returned at once (notebook lead13)
  local name=$1; shift
  rm -f "$RUNS/pids/$name"
  setsid bash -c 'echo $$ > "$0"; exec bash -c "$1"' "$RUNS/pids/$name" "$*" \
    > "$RUNS/logs/$name-$(date +%s).log" 2>&1 < /dev/null &
  for _ in 1 2 3 4 5 6 7 8 9 10; do [ -s "$RUNS/pids/$name" ] && break; sleep 0.2; done
  echo "$name started (pid $(cat "$RUNS/pids/$name" 2>/dev/null))"
}

collect() {  # the logs, the curve and the results into $OUT (at most 8 files come back)
  tar czf "$OUT/logs.tgz" -C "$RUNS" logs
  local runs=()
  for n in $SIZES; do
    logs=$(ls "$RUNS"/logs/train-"$n"-*.log 2>/dev/null | sort | paste -sd,)
    [ -n "$logs" ] && runs+=("$n=$logs")
  done
  [ ${#runs[@]} -gt 0 ] && $PY -m benchmarks.diffusion_curve --json "$OUT/diffusion-curve.json" \
    --png "$OUT/diffusion-curve.png" "${runs[@]}"
  cp "$RUNS"/results/* "$OUT/results/" 2>/dev/null
  return 0
}

for stage in "$@"; do
  n=${stage##*-}
  case "$stage" in
    demos-*)
      t0=$(date +%s.%N)
      $PY -m mjx_pusht demos --task gym-pusht --seeds "10000:$((10000 + n))" --successful-only --replace \
        --out "$RUNS/demos-$n" --no-progress > "$RUNS/logs/demos-$n.log" 2>&1
      rc=$?; t1=$(date +%s.%N); cat "$RUNS/logs/demos-$n.log"
      $PY -c "import json, sys; i = json.load(open(sys.argv[1])) if sys.argv[2] == '0' else {}
print(json.dumps({'command': 'mjx-pusht demos --task gym-pusht --seeds 10000:' + str(10000 + int(sys.argv[3]))
      + ' --successful-only', 'rc': int(sys.argv[2]), 'wall_s': float(sys.argv[5]) - float(sys.argv[4]),
      'episodes': i.get('total_episodes'), 'frames': i.get('total_frames')}))" \
        "$RUNS/demos-$n/meta/info.json" "$rc" "$n" "$t0" "$t1" | tee -a "$RUNS/results/diffusion-demos.jsonl" ;;
    rate)
      for s in $SIZES; do
        rm -rf "$RUNS/rate-$s"
        $PY -m lerobot.scripts.lerobot_train --dataset.repo_id="local/mjx_pusht_demos_$s" \
          --dataset.root="$RUNS/demos-$s" $(policy_args) --steps="$RATE_STEPS" --env_eval_freq=0 \
          --save_checkpoint=false --output_dir="$RUNS/rate-$s" > "$RUNS/logs/rate-$s.log" 2>&1 &
      done
      wait
      $PY - "$RUNS" "$MINUTES" "$POINTS" $SIZES > "$RUNS/results/diffusion-rate.json" <<'PYEOF'
import json, re, sys
runs, minutes, points, sizes = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
row = {"minutes": minutes, "side_by_side": sizes}
for s in sizes:
    log = open(f"{runs}/logs/rate-{s}.log").read()
    t = [float(a) + float(b) for a, b in re.findall(r"updt_s:([0-9.]+) data_s:([0-9.]+)", log)]
    if len(t) < 2:
        sys.exit(f"rate-{s}.log has {len(t)} log lines: RATE_STEPS must be at least twice --log_freq (100)")
    per_step = sum(t[1:]) / len(t[1:])  # the first window holds the start-up
    steps = int(minutes * 60 / per_step)
    # the values to run train-N with: STEPS for MINUTES of updates, POINTS curve points, a checkpoint every ~2 minutes
    row[s] = {"s_per_step": per_step, "STEPS": steps, "EVAL_FREQ": max(100, int(round(steps / points, -2))),
              "SAVE_FREQ": max(100, int(round(120 / per_step, -2)))}
print(json.dumps(row))
PYEOF
      cat "$RUNS/results/diffusion-rate.json" ;;
    train-*)
      last="$RUNS/train-$n/checkpoints/last/pretrained_model/train_config.json"
      if [ -f "$last" ]; then  # LeRobot's own resume: its config, optimizer, scheduler, RNG and data order
        [ -z "$FROM" ] || echo "train-$n: resuming its own checkpoint in $RUNS/train-$n; FROM is not used" >&2
        read -r steps save_freq < <($PY -c "import json, sys; c = json.load(open(sys.argv[1]))
print(c['steps'], c['save_freq'])" "$last") || exit 1
        stop_at "$steps" "$save_freq" "$((10#$(readlink "$RUNS/train-$n/checkpoints/last")))"
        detach "train-$n" "$PY -m $(trainer) --config_path=$last --resume=true"
      else
        if [ "$STEPS" = rated ]; then  # this size's row of the rate stage's JSON
          read -r steps eval_freq save_freq < <($PY -c "import json, sys; r = json.load(open(sys.argv[1]))[sys.argv[2]]
print(r['STEPS'], r['EVAL_FREQ'], r['SAVE_FREQ'])" "$RUNS/results/diffusion-rate.json" "$n") || exit 1
        else steps=$STEPS eval_freq=$EVAL_FREQ save_freq=$SAVE_FREQ; fi
        stop_at "$steps" "$save_freq"
        detach "train-$n" "$PY -m $(trainer) --dataset.repo_id=local/mjx_pusht_demos_$n \
          --dataset.root=$RUNS/demos-$n $(policy_args) $(EVAL_FREQ=$eval_freq env_args) --steps=$steps --save_freq=$save_freq \
          --output_dir=$RUNS/train-$n"
      fi ;;
    eval-final-*)
      ckpt="$RUNS/train-$n/checkpoints/last/pretrained_model"
      ev="$PY -m benchmarks.lerobot_eval --policy $ckpt --device $DEVICE --episodes 500 --batch 500 \
          --out $RUNS/eval-$n --json $RUNS/results/diffusion-eval-$n.json"
      if [ -n "$EVAL_GPUS" ]; then  # a host of several GPUs: each env on a GPU of its own, at the same time (a
        read -r g1 g2 <<< "$EVAL_GPUS"  # hold's minutes; neither shares a GPU, and the host's cores far outnumber two)
        CUDA_VISIBLE_DEVICES=$g1 detach "eval-final-$n-mjx_pusht" "$ev --env mjx_pusht"
        CUDA_VISIBLE_DEVICES=${g2:-$g1} detach "eval-final-$n-pusht" "$ev --env pusht"
      else detach "eval-final-$n" "$ev --env mjx_pusht; $ev --env pusht"; fi ;;  # the second runs whatever the first gave
    wait)
      end=$(( $(date +%s) + WAIT_MIN * 60 ))
      while [ "$(date +%s)" -lt "$end" ]; do
        alive=0
        for f in "$RUNS"/pids/*; do [ -f "$f" ] && kill -0 "$(cat "$f")" 2>/dev/null && alive=1; done
        [ $alive = 0 ] && break
        sleep 10
      done
      for f in "$RUNS"/pids/*; do
        [ -f "$f" ] || continue
        if kill -0 "$(cat "$f")" 2>/dev/null; then echo "$(basename "$f") still running"
        else echo "$(basename "$f") ended"; rm "$f"; fi
      done
      for log in "$RUNS"/logs/*.log; do echo "== $log"; grep -a "INFO" "$log" | tail -n 2 | cut -c1-300; done
      collect ;;
    pack-*|send|unpack-*)  # a run carried out of one hold and into the next (tools/offline-gpu/carry_run.sh)
      RUNS=$RUNS OUT=$OUT CARRIED=$CARRIED bash tools/offline-gpu/carry_run.sh "$stage" || exit ;;
    bundle)  # what `wait` collected as one file, diffusion.tgz (a call brings back at most 8)
      collect; (cd "$OUT" && tar czf diffusion.tgz --remove-files logs.tgz results diffusion-curve.* 2>/dev/null); ls -l "$OUT" ;;
    *) echo "unknown stage $stage (demos-N rate train-N eval-final-N wait bundle pack-N send unpack-N)"; exit 2 ;;
  esac
  echo "$stage done"
done
