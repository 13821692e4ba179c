"""LeRobot 0.6.1's own `lerobot-train` (its command line, its loop, its checkpoints), ended once the checkpoint of a
given step is written whole: a run whose cosine schedule is `--steps` long, cut short where an earlier run was cut,
so the two compare at equal updates on the same schedule (docs/lerobot-diffusion.md, the sizes). LeRobot has no such
stop (its schedule's length is `--steps`), and a stop from outside, polling the checkpoints, misses the step where
checkpoints come faster than the poll (a small run on a CPU writes the next within a second).

    python -m benchmarks.lerobot_train_until STEP [lerobot-train's arguments]
"""

from __future__ import annotations

import sys
from pathlib import Path

from lerobot.scripts import lerobot_train


def main() -> None:
    if len(sys.argv) < 2 or not sys.argv[1].isdigit() or int(sys.argv[1]) < 1:
        sys.exit("usage: python -m benchmarks.lerobot_train_until STEP [lerobot-train's arguments], STEP a whole "
                 f"number above 0 (got {sys.argv[1:2] or 'nothing'})")
    stop_at = int(sys.argv.pop(1))  # the rest is lerobot-train's own command line, parsed by LeRobot
    update_last_checkpoint = lerobot_train.update_last_checkpoint

    def point_last_then_stop(checkpoint_dir: Path) -> None:
        # LeRobot points `last` at a checkpoint after writing all of it (model, optimizer, scheduler, RNG), so the
        # run stops with a checkpoint its --resume and lerobot-eval take as any other
        update_last_checkpoint(checkpoint_dir)
        if int(Path(checkpoint_dir).name) == stop_at:
            print(f"STOP_AT: the step-{stop_at} checkpoint is saved; stopping the run", flush=True)
            raise SystemExit(0)

    lerobot_train.update_last_checkpoint = point_last_then_stop
    lerobot_train.main()


if __name__ == "__main__":
    main()
