#!/usr/bin/env bash
# A training run's whole state out of one GPU host and into the next, as parts small enough for whatever carries
# files off and onto a host with no registry and no network (docs/offline-gpu.md). The run is $RUNS/train-N, as
# benchmarks/diffusion_pusht.sh lays it out (LeRobot's output folder: checkpoints/NNNNNN, checkpoints/last), its
# logs in $RUNS/logs, a detached training's pid in $RUNS/pids/train-N.
#   bash tools/offline-gpu/carry_run.sh pack-N     # there: the last checkpoint and the logs as 15 MiB parts in $RUNS/pack
#   bash tools/offline-gpu/carry_run.sh send       # there: the next 4 parts (and the checksums) under $OUT/parts
#   bash tools/offline-gpu/carry_run.sh unpack-N   # the next host: the parts gathered in $CARRIED, checked, unpacked
# PACK=resume (default): the checkpoint LeRobot's --resume restarts from (model, optimizer, scheduler, RNG), a
# training still running stopped first; PACK=model: the policy's pretrained_model folder alone; PACK=live: the
# checkpoint `last` names now, the training left running (LeRobot points `last` at a step only once it is written).
# benchmarks/diffusion_pusht.sh runs these stages under the same names.
set -uo pipefail
RUNS=${RUNS:-$HOME/diffusion}
OUT=${OUT:-outputs/bench-diffusion}
CARRIED=${CARRIED:-$HOME/carried}  # where the carried parts of a packed run are gathered
case "${PACK:-resume}" in resume|model|live) ;; *) echo "PACK must be resume, model or live, got '$PACK'" >&2; exit 2 ;; esac
for stage in "$@"; do
  n=${stage##*-}
  case "$stage" in
    pack-*)
      # a training still running would write a checkpoint under tar's feet: stop it first (its last checkpoint is
      # what a resume restarts from, so call pack-N just after one: SAVE_FREQ's line in the log)
      if [ "${PACK:-resume}" != live ] && [ -f "$RUNS/pids/train-$n" ] && kill -0 "$(cat "$RUNS/pids/train-$n")" 2>/dev/null; then
        kill -TERM -- "-$(cat "$RUNS/pids/train-$n")"
        for _ in $(seq 60); do kill -0 "$(cat "$RUNS/pids/train-$n")" 2>/dev/null || break; sleep 0.5; done
        echo "pack-$n: stopped the running train-$n"
      fi
      step=$(readlink "$RUNS/train-$n/checkpoints/last") || {
        echo "pack-$n: $RUNS/train-$n has no checkpoint to pack" >&2; exit 1; }
      mkdir -p "$RUNS/pack" && rm -f "$RUNS/pack/train-$n".* "$RUNS/pack/sent"
      # `last` as read above, not as the running training may have moved it since: a link of our own to $step
      rm -rf "$RUNS/pack/link" && mkdir -p "$RUNS/pack/link/train-$n/checkpoints" && ln -s "$step" "$RUNS/pack/link/train-$n/checkpoints/last"
      what=("train-$n/checkpoints/$step" logs -C "$RUNS/pack/link" "train-$n/checkpoints/last")
      # PACK=model: the policy alone (114 MB, 2 send calls), to score it elsewhere or start a run FROM it
      [ "${PACK:-resume}" = model ] && what=("train-$n/checkpoints/$step/pretrained_model")
      # (live: the log being written as tar reads it is no error, its copy ends where tar read it)
      tar cf - --warning=no-file-changed -C "$RUNS" "${what[@]}" \
        | split -b 15m -d -a 3 - "$RUNS/pack/train-$n.tar.part."
      (cd "$RUNS/pack" && sha256sum train-"$n".tar.part.* > "train-$n.sha256")
      ls -l "$RUNS/pack"; echo "then: send, once per 4 parts" ;;
    send)  # the next 4 parts not yet sent (and the checksums), under $OUT/parts
      mkdir -p "$OUT/parts" && touch "$RUNS/pack/sent"
      cp "$RUNS"/pack/*.sha256 "$OUT/parts/"
      k=0
      for p in "$RUNS"/pack/*.part.*; do
        grep -qx "$p" "$RUNS/pack/sent" && continue
        [ $k -ge 4 ] && { echo "more parts: send again"; break; }
        cp "$p" "$OUT/parts/" && echo "$p" >> "$RUNS/pack/sent"; k=$((k + 1))
      done
      [ $k = 0 ] && echo "every part was sent already"
      ls "$OUT/parts" ;;
    unpack-*)
      (cd "$CARRIED" && sha256sum -c --quiet "train-$n.sha256") > /dev/null 2>&1 || {
        echo "unpack-$n: parts missing or damaged in $CARRIED (sha256sum -c train-$n.sha256 there names them)" >&2; exit 1; }
      mkdir -p "$RUNS" && cat "$CARRIED"/train-"$n".tar.part.* | tar xf - -C "$RUNS" && ls "$RUNS/train-$n/checkpoints" ;;
    *) echo "unknown stage $stage (pack-N send unpack-N)" >&2; exit 2 ;;
  esac
done
