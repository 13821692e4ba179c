"""The train command's defaults are the recipes measured. DAgger from gym-pusht's image and agent_pos on MJX takes,
flag for flag, what the committed runs that reached 97.5% and 97.9% held-out were given (their own command lines,
parsed by the same parser); a flag given still wins; the chapter's, the CPU's and PPO's defaults stay theirs."""

import json
from pathlib import Path

import pytest

from mjx_pusht.cli.parser import build_parser
from mjx_pusht.cli.train import _method_settings

RUNS = Path(__file__).parents[1] / "outputs/reports/train/dagger-pixels-gym-pusht-h200-16k"
PIXELS = ["--obs", "pixels_agent_pos", "--task", "gym-pusht", "--backend", "mjx-warp"]
OWN = {"seed", "out", "record", "progress", "rerun"}  # a run's own, not its recipe's


def settings(argv: list[str], backend: str = "mjx-warp"):
    args = build_parser().parse_args(["train", *argv])
    _method_settings(args, backend)
    return args


@pytest.mark.parametrize("seed", [0, 1])
def test_the_pixel_recipe_is_the_committed_runs(seed):
    run = json.loads((RUNS / f"seed-{seed}/summary.json").read_text())
    command = (RUNS / f"log-seed-{seed}.txt").read_text().splitlines()[0]
    ran = settings(command.split(" -m mjx_pusht train ")[1].split())
    assert ran.seed == run["config"]["seed"] == seed and list(ran.hidden) == run["config"]["hidden"]
    assert run["held_out_success"] >= 0.97 and run["wall_seconds"] <= ran.minutes * 60
    default = settings(PIXELS)
    differ = {k: (getattr(default, k), v) for k, v in vars(ran).items() if k not in OWN and getattr(default, k) != v}
    assert not differ  # (the default, the run's) for any setting where they part


def test_a_flag_given_wins_over_the_recipe():
    args = settings([*PIXELS, "--envs", "4096", "--keep", "last", "--hidden", "64,64", "--minutes", "3"])
    assert (args.envs, args.keep, tuple(args.hidden), args.minutes) == (4096, "last", (64, 64), 3.0)
    assert args.max_samples == 32_000_000  # the rest stays the recipe's


@pytest.mark.parametrize("argv, backend, expected", [
    (["--obs", "pixels_agent_pos", "--backend", "mjx-warp"], "mjx-warp", (4096, (256, 256, 256), 10, "last", None)),
    (["--obs", "keypoints", "--task", "gym-pusht", "--backend", "mjx-warp"], "mjx-warp",
     (4096, (256, 256, 256), 10, "last", None)),
    (["--task", "gym-pusht", "--backend", "cpu"], "cpu", (256, (256, 256, 256), 10, "last", None)),
    (["--algo", "ppo", "--obs", "pixels_agent_pos", "--task", "gym-pusht", "--backend", "mjx-warp"], "mjx-warp",
     (4096, (256, 256, 256), 10, "last", None)),
])
def test_other_runs_keep_their_defaults(argv, backend, expected):
    args = settings(argv, backend)
    assert (args.envs, tuple(args.hidden), args.iterations, args.keep, args.minutes) == expected
