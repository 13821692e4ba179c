"""The `mjx-pusht` argument parser: the commands' flags and their one-line errors (the flags' value types:
flagtypes.py)."""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

from mjx_pusht.cli import flagtypes as ft
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.model.scene import BREAK_MODES


class UsageError(MjxPushtError):
    """Bad input: printed as one line, exit 2."""


_GIVEN = "_flags_given"  # the flags a parse has met, by dest; gone from the namespace it returns
# flags whose repeats are their meaning (--param NAME=VALUES per parameter), or that end the parse (--help)
_REPEATABLE = (argparse._AppendAction, argparse._AppendConstAction, argparse._CountAction, argparse._HelpAction,
               argparse._VersionAction)


class _Parser(argparse.ArgumentParser):
    """One-line errors, and each flag at most once: argparse lets the last of `--seeds 2 --seeds 3` win and drops the
    first without a word (the thirteenth pass); what the package cannot honour, it refuses."""

    def error(self, message: str):  # one line, no usage dump
        raise UsageError(message)

    def add_argument(self, *args, **kwargs):
        action = super().add_argument(*args, **kwargs)
        if action.option_strings and not isinstance(action, (*_REPEATABLE, _Once)):
            action.__class__ = _given_once(type(action))
        return action

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        namespace.__dict__.pop(_GIVEN, None)
        return namespace, extras


@functools.cache
def _given_once(cls: type) -> type:
    """`cls` refusing a second use of its flag in one parse (aliases and prefixes of it count as the flag)."""

    class Once(cls):
        def __call__(self, parser, namespace, values, option_string=None):
            given = namespace.__dict__.setdefault(_GIVEN, set())
            if self.dest in given:
                raise argparse.ArgumentError(self, "given twice: give it once")
            given.add(self.dest)
            super().__call__(parser, namespace, values, option_string)

    Once.__name__ = Once.__qualname__ = cls.__name__
    return Once


def success_arg(p: argparse.ArgumentParser) -> None:
    """--success-threshold: the coverage an episode succeeds at (every command that judges success takes it)."""
    p.add_argument("--success-threshold", type=ft.threshold, default=None, metavar="COVERAGE",
                   help="the coverage of the target an episode succeeds (and ends) at, in (0, 1] (default: the "
                        "task's own, 0.95; ManiSkill's PushT scores at 0.9)")


REPLACE_HELP = ("overwrite this command's finished results of other seeds or settings in --out (set aside until this run "
                "finishes; a run that fails puts them back); another command's results are never overwritten")
SHARE_HELP = ("write into an --out that holds files this command did not write (they are left alone; by default such "
              "an --out is refused)")


def _batch_args(p: argparse.ArgumentParser, name: str, rows: str, *, seeds: str) -> None:
    """The options every batch command shares: seeds, backend, scene, output, chunks, recording, parameters."""
    p.add_argument("--seeds", default=seeds, help=f"N (0..N-1), A:B, or a,b,c (default {seeds})")
    p.add_argument("--backend", default="auto", help="auto, cpu, mjx-jax or mjx-warp (default auto)"
                   + ("; gym-pusht: gym-pusht 0.1.8 itself, for --task gym-pusht" if name == "eval" else ""))
    p.add_argument("--break", dest="break_it", choices=BREAK_MODES, default="none")
    p.add_argument("--out", type=ft.folder, default=Path(f"outputs/{name}"), help=f"the run's folder (default outputs/{name})")
    p.add_argument("--chunk", type=ft.rows, default=None, help=f"{rows} per batch (default: by backend)")
    p.add_argument("--resume", action="store_true", help=f"finish an interrupted {name} in --out")
    p.add_argument("--replace", action="store_true", help=REPLACE_HELP)
    p.add_argument("--share-out", action="store_true", help=SHARE_HELP)
    p.add_argument("--record", type=ft.nonneg, default=None,  # None: unset, so that one --no-rerun skips is refused
                   help=f"{rows} to show side by side in {name}.rrd (default 4)")
    p.add_argument("--no-rerun", dest="rerun", action="store_false", help=f"skip {name}.rrd")
    p.add_argument("--no-progress", dest="progress", action="store_false")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUES",
                   help="sweep a physical parameter as a grid: kv, kp (gym-pusht), tee_damping, tee_frictionloss, tee_mass; "
                        "VALUES is a,b,c, lo:hi:n (evenly spaced) or ~lo:hi:n (n random draws) (repeatable)")
    randomize_arg(p)


def _randomize(text: str) -> dict:
    """An argparse type: --randomize's NAME=lo:hi,... (model/randomize.parse), its error one line."""
    from mjx_pusht.model.params import ParamError
    from mjx_pusht.model.randomize import parse

    try:
        return parse(text)
    except ParamError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


class _Once(argparse.Action):
    """A flag whose one value names several things (--randomize's parameters): a second one is refused, not taken
    over the first (the eleventh pass: `--randomize tee_mass=0.5:2 --randomize kv=0.9:1.1` drew kv alone)."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest) is not None:
            raise argparse.ArgumentError(self, "given twice: give it once, its parameters comma-separated "
                                               "(e.g. tee_mass=0.5:2,kv=0.8:1.2)")
        setattr(namespace, self.dest, values)


def randomize_arg(p: argparse.ArgumentParser) -> None:
    """--randomize: physics drawn per episode from its seed (eval, sweep, train)."""
    p.add_argument("--randomize", type=_randomize, default=None, action=_Once, metavar="NAME=LO:HI,...",
                   help="draw physics per episode from its seed: scale factors on the task's own values, uniform in "
                        "[LO, HI] (LO = HI: fixed). chapter: tee_mass, tee_damping, tee_frictionloss, kv; gym-pusht: "
                        "kp, kv (e.g. tee_mass=0.5:2,kv=0.8:1.2)")


def _task_args(p: argparse.ArgumentParser, reset_help: str) -> None:
    """--task, the chapter task's --reset (task/tasks.py), --goal and --success-threshold."""
    from mjx_pusht.task.tasks import TASKS

    p.add_argument("--task", choices=tuple(TASKS), default="chapter",
                   help="; ".join(f"{t.name}: {t.about}" for t in TASKS.values()) + " (default chapter)")
    p.add_argument("--reset", choices=TASKS["chapter"].resets, default=None, help=reset_help)
    p.add_argument("--goal", choices=("fixed", "random"), default="fixed",
                   help="fixed: the target at the centre (default); random: a goal pose per episode from its seed, "
                        "anywhere the T can be pushed to")
    success_arg(p)


def _process_args(p: argparse.ArgumentParser, what: str, writes: str) -> None:
    """Several processes joined through jax.distributed (study/distributed.py): sweep and train."""
    p.add_argument("--num-processes", type=ft.positive, default=1,
                   help=f"processes sharing this {what} through jax.distributed, one a host or GPU (default 1)")
    p.add_argument("--process-id", type=ft.nonneg, default=0, help=f"this process's index, 0 .. N-1 (0 writes {writes})")
    p.add_argument("--coordinator", default=None, metavar="HOST:PORT", help="where process 0 listens")
    p.add_argument("--peer-timeout", type=ft.positive_float, default=None, metavar="SECONDS",
                   help="how long to wait for every process to join before giving up (default 300)")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="mjx-pusht", description="PushT in MuJoCo at scale: CPU reference and MJX batch.")
    p.add_argument("--verbose", action="store_true",
                   help="show the libraries' own set-up chatter (Warp's banner and its kernel module loads)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("scene", help="the chapter's run: one seed, settle, push, weld check, recording")
    s.add_argument("--seed", type=ft.seed, default=0, help="seeds the block's start pose, like a PushT reset")
    s.add_argument("--steps", type=ft.steps, default=None, help="nudge length in steps (default 120; not with --smoke)")
    s.add_argument("--smoke", action="store_true", help="fixed 120-step run; two runs match byte for byte")
    s.add_argument("--out", type=ft.folder, default=Path("outputs/scene"), help="the run's folder (default outputs/scene)")
    s.add_argument("--replace", action="store_true", help=REPLACE_HELP)
    s.add_argument("--share-out", action="store_true", help=SHARE_HELP)
    s.add_argument("--no-rerun", dest="rerun", action="store_false", help="skip the .rrd recording")
    s.add_argument("--break", dest="break_it", choices=BREAK_MODES, default="none")
    s.add_argument("--compare-welded", action="store_true",
                   help="with --break: also run the welded T and record both side by side in walk.rrd "
                        "(the chapter's diagnosis walk)")

    t = sub.add_parser("tree", help="print the compiled kinematic tree")
    t.add_argument("--break", dest="break_it", choices=BREAK_MODES, default="none")
    t.add_argument("--pusher", choices=("cylinder", "capsule"), default="cylinder")
    t.add_argument("--json", action="store_true")
    t.add_argument("--colliders", action="store_true",
                   help="for every collidable geom pair: the collision function MuJoCo C, MJX-Warp and MJX-JAX call")

    w = sub.add_parser("sweep", help="many seeds at once on a backend; per_seed.parquet + summary.json")
    _batch_args(w, "sweep", "seeds", seeds="4096")
    w.add_argument("--steps", type=ft.steps, default=120, help="nudge length in steps (default 120)")
    w.add_argument("--audit", type=ft.fraction, default=None, metavar="FRACTION",
                   help="MJX backends: re-run this fraction of the rows (at least 64, at most 16,384) plus every "
                        "flagged row on the CPU reference and record whether they agree (default 0.01; 0 skips)")
    _process_args(w, "sweep", "the table")

    e = sub.add_parser("eval", help="a controller on many start states: per_episode.parquet, success rate + interval")
    _batch_args(e, "eval", "episodes", seeds="512")
    e.add_argument("--controller", default="expert",
                   help="zero, nudge, random, expert (default), a trained policy as policy:PATH, or your own "
                        "as package.module:function")
    e.add_argument("--action", choices=("velocity", "position"), default=None,
                   help="what your controller's actions mean (default velocity; built-ins command velocities)")
    _task_args(e, "start distribution of the chapter task (default task; gym-pusht's task has its own)")
    e.add_argument("--max-steps", type=ft.steps, default=300, help="control steps before truncation (default 300)")
    e.add_argument("--frame-skip", type=ft.frame_skip, default=10, help="physics steps per control step (default 10)")
    e.add_argument("--video", type=ft.video_file, default=None, metavar="FILE.gif|FILE.mp4",
                   help="the first --video-episodes episodes as a grid of tiles, coverage on each (rendered on the CPU)")
    # None by default, so that one given without --video is seen (and refused, not ignored)
    e.add_argument("--video-episodes", type=ft.positive, default=None, help="tiles in --video (default 16)")
    e.add_argument("--video-size", type=ft.int_at_least(32, 2048), default=None,
                   help="pixels per tile side in --video (default 128)")

    t = sub.add_parser("train", help="train a policy (DAgger from the expert, or Brax PPO): policy.msgpack, curve, summary")
    t.add_argument("--algo", choices=("dagger", "ppo"), default="dagger",
                   help="dagger (distil the expert) or ppo (Brax's PPO on a shaped reward; mjx backends only)")
    t.add_argument("--obs", choices=("state", "keypoints", "pixels_agent_pos"), default="state",
                   help="what the policy sees (default state; pixels_agent_pos: the 96 x 96 top camera and the "
                        "pusher's position, DAgger only)")
    t.add_argument("--backend", default="auto", help="auto, cpu, mjx-jax or mjx-warp (default auto)")
    t.add_argument("--devices", type=ft.positive, default=None,
                   help="mjx backends: this many of the host's devices (GPUs) roll out and learn, each its share of "
                        "the episodes and of every minibatch, gradients averaged (default: every one)")
    _process_args(t, "training run (its episodes and minibatches split over every process's devices)",
                  "the run's files")
    t.add_argument("--out", type=ft.folder, default=Path("outputs/train"), help="the run's folder (default outputs/train)")
    t.add_argument("--replace", action="store_true", help=REPLACE_HELP)
    t.add_argument("--share-out", action="store_true", help=SHARE_HELP)
    t.add_argument("--envs", type=ft.worlds, default=None,
                   help="episodes rolled out per iteration (default 4096; DAgger on cpu 256; 16384 in the pixel recipe)")
    t.add_argument("--iterations", type=ft.positive, default=None,
                   help="DAgger iterations, or PPO's held-out judgements over the run (default 10; 300 in the pixel "
                        "recipe: DAgger from pixels_agent_pos on gym-pusht's task on MJX, docs/training.md)")
    t.add_argument("--timesteps", type=ft.int_at_least(1, 10**15), default=None, help="PPO: env control steps in all (default 50M)")
    t.add_argument("--fit-steps", type=ft.positive, default=None,
                   help="DAgger: gradient steps per iteration (default 2000; on cpu 1000; 10000 in the pixel recipe)")
    t.add_argument("--batch", type=ft.positive, default=None,
                   help="DAgger: samples per gradient step (default 4096; on cpu 1024); PPO: Brax's batch_size "
                        "(default 256)")
    t.add_argument("--image-batch", type=ft.positive, default=None,
                   help="DAgger from pixels: of each step's --batch samples, how many are rendered to teach the image "
                        "trunk the T's pose (all teach the actions from the true pose; default 512, at most --batch)")
    t.add_argument("--image-steps", type=ft.positive, default=None,
                   help="DAgger from pixels: gradient steps an iteration that teach the image trunk the T's pose, "
                        "apart from the --fit-steps that teach the actions (default: as many as --fit-steps; 4000 in the pixel recipe)")
    t.add_argument("--late-fits", type=ft.positive, default=None,
                   help="DAgger: fits of --fit-steps after each rollout once the expert's share is at most 1%% "
                        "(default 1): late in a run the student under-fits a ring that changes little")
    t.add_argument("--first-fits", type=ft.positive, default=None,
                   help="DAgger: the first fit is made from this many initialisations and the one with the lowest "
                        "training loss kept (default 1; 4 in the pixel recipe): where a run starts, its loss holds through the run")
    t.add_argument("--action-eps", type=lambda v: ft.positive_or_off(v, 1e3),  # squared in float32: 1e308 overflowed default=None,
                   help="DAgger: weigh each action's squared error by (0.1^2 + eps^2) / (|label|^2 + eps^2), eps in m/s "
                        "('off': plain squared error; default: the task's, gym-pusht 0.01, chapter off): a nudge of a "
                        "few mm is learned as precisely, relative to its size, as a 0.1 m/s move")
    t.add_argument("--keep", choices=("last", "best"), default=None,
                   help="DAgger: the run's policy is the last fit (default; best in the pixel recipe), or the fit whose next rollout succeeded "
                        "most on that iteration's fresh training seeds once the expert's share there is at most 1%%; "
                        "PPO: the judged policy that succeeded most on validation seeds past its training starts "
                        "(both chosen without the held-out seeds)")
    t.add_argument("--ppo-act", choices=("sample", "mean"), default=None,
                   help="PPO: the saved policy acts with a draw from its Gaussian keyed by seed and step, what PPO "
                        "trains (default), or with the Gaussian's mean, Brax's deterministic action")
    t.add_argument("--max-grad-norm", type=ft.positive_or_off, default=None,
                   help="clip the gradient's global norm to this before Adam (default 1.0; 'off': unclipped). PPO: "
                        "Brax's max_grad_norm (unclipped runs collapsed from 99-100%% to 0-6%% and back); DAgger: every "
                        "fit (unclipped, 3 of 16 first fits landed where the student succeeds on 0-0.2%%)")
    t.add_argument("--lr-schedule", choices=("adaptive-kl",), default=None,
                   help="PPO: adaptive-kl, Brax's ADAPTIVE_KL (the rate follows the epochs' KL toward 0.01); "
                        "default a constant rate")
    t.add_argument("--minibatches", type=ft.positive, default=None,
                   help="PPO: Brax's num_minibatches, each of --batch unrolls (default 32): a round of updates takes "
                        "--batch x this x 20 env steps")
    t.add_argument("--hidden", type=ft.widths, default=None,
                   help="hidden widths (default 256,256,256; 1024,1024,1024 in the pixel recipe)")
    t.add_argument("--lr", type=ft.learning_rate, default=None, help="Adam's learning rate (default 1e-3; PPO 3e-4)")
    t.add_argument("--beta-decay", type=ft.fraction, default=None,
                   help="DAgger: the expert's share of control steps: 1, then times this each iteration (default 0.7)")
    t.add_argument("--teacher", choices=("paced", "expert"), default=None,
                   help="DAgger: whom the student learns from: the expert paced for a student (its slowest actions "
                        "faster, its last trims coarser, so a student's small errors still move the T; default), or "
                        "the expert as is")
    t.add_argument("--max-samples", type=ft.int_at_least(1, 1 << 30, " samples"), default=None,
                   help="DAgger: dataset ring size (default 8,000,000; 32,000,000 in the pixel recipe)")
    _task_args(t, "start distribution of the chapter task trained and judged on (default task)")
    randomize_arg(t)  # training's episodes and every held-out judgement at each episode's drawn physics
    t.add_argument("--eval-envs", type=ft.worlds, default=None,
                   help="held-out task seeds judged after every iteration (default 4096; DAgger on cpu 64)")
    t.add_argument("--max-steps", type=ft.steps, default=300,
                   help="control steps before an episode is truncated, in training and in every judgement (default "
                        "300, the task's; eval --max-steps judges a policy at the same length)")
    t.add_argument("--minutes", type=ft.positive_float, default=None,
                   help="training's budget, its last judgement included: no rollout or fit starts that would pass it "
                        "(default none; 19.5 in the pixel recipe)")
    t.add_argument("--until", type=ft.rate, default=None, metavar="SUCCESS",
                   help="stop at the first held-out judgement at or above this success rate, in (0, 1] (the time "
                        "to a goal rate; the stop chose that judgement, so judge the policy again on other seeds, "
                        "eval --seeds, for a rate the stop did not pick)")
    t.add_argument("--seed", type=ft.train_seed, default=0, help="initialisation and sampling seed (default 0)")
    t.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    t.add_argument("--record", type=ft.nonneg, default=None, help="held-out episodes in eval/eval.rrd (default 4)")
    t.add_argument("--no-rerun", dest="rerun", action="store_false", help="skip train.rrd and eval/eval.rrd")
    t.add_argument("--no-progress", dest="progress", action="store_false")

    c = sub.add_parser("compare", help="CPU vs MJX fidelity report: compare.json, compare.md, compare.png")
    c.add_argument("--seeds", default=None, help="N, A:B or a,b,c (default 64; not with --evals: theirs)")
    c.add_argument("--backend", default=None, help="mjx-jax or mjx-warp (default mjx-jax); gym-pusht: gym-pusht "
                                                         "0.1.8 itself, for --task gym-pusht --controller C")
    c.add_argument("--out", type=ft.folder, default=Path("outputs/compare"),
                   help="the report's folder (default outputs/compare)")
    c.add_argument("--replace", action="store_true", help=REPLACE_HELP)
    c.add_argument("--share-out", action="store_true", help=SHARE_HELP)
    c.add_argument("--no-root-cause", dest="root_cause", action="store_false",
                   help="skip the one-change-at-a-time runs (x64, solver, contact census)")
    c.add_argument("--tolerance", type=ft.positive_float, default=None,
                   help="MJX solver tolerance instead of the scene's 1e-8 (the CPU reference keeps its own)")
    c.add_argument("--iterations", type=ft.positive, default=None, help="MJX solver iterations instead of the scene's")
    c.add_argument("--controller", default=None,
                   help="compare closed-loop episodes of this controller instead (e.g. expert): success rates, "
                        "per-seed agreement, final poses")
    _task_args(c, "closed loop: start distribution of the chapter task (default task)")
    c.add_argument("--max-steps", type=ft.steps, default=None, help="closed loop: control steps per episode (default 300)")
    c.add_argument("--evals", nargs=2, type=Path, metavar=("EVAL_DIR", "EVAL_DIR"), default=None,
                   help="pair two finished eval folders of the same controller and seeds, one run on the cpu backend "
                        "and one on MJX or gym-pusht (e.g. on two machines), into the closed-loop report; runs nothing")

    from mjx_pusht.cli.demos import add_parser as add_demos

    add_demos(sub, rows=ft.rows, steps=ft.steps, folder=ft.folder, replace_help=REPLACE_HELP, share_help=SHARE_HELP,
              success=success_arg)
    return p


def unread_flags(args) -> None:
    """Refuse a flag the command would not read (cli.md: refused, not ignored), then fill the defaults those flags
    leave None so that a given one is seen: --record with --no-rerun, --peer-timeout with one process."""
    if getattr(args, "rerun", True) is False and getattr(args, "record", None):  # (--record 0 asks for nothing)
        raise UsageError(f"--record {args.record} picks what the recording shows, which --no-rerun skips: give one")
    if getattr(args, "resume", False) and getattr(args, "replace", False):  # each undoes the other (an eval's
        # --replace removed the finished results, then ran afresh under --resume)
        raise UsageError("--resume continues the run in --out and --replace starts it over: give one")
    if getattr(args, "peer_timeout", None) is not None and getattr(args, "num_processes", 1) == 1:
        raise UsageError("--peer-timeout waits for the other processes; one process waits for none: give "
                         "--num-processes N with it, or leave it out")
    for name, default in (("record", 4), ("peer_timeout", 300.0)):
        if hasattr(args, name) and getattr(args, name) is None:
            setattr(args, name, default)
