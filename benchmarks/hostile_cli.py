"""The hostile pass's CLI tries (hostile_pass.py runs and judges them): every command's flags, bad and odd."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

from benchmarks.hostile_pass import Try, run_cli

CONTROLLERS = '''
import numpy as np
def nan(obs, t): return np.full(obs["state"].shape[:-1] + (2,), np.nan)
def inf_later(obs, t): return np.full(obs["state"].shape[:-1] + (2,), np.inf if t >= 2 else 0.0)
def neg_inf_one_row(obs, t):
    a = np.zeros(obs["state"].shape[:-1] + (2,)); a[..., -1:, 0] = -np.inf; return a
def shape(obs, t): return np.zeros(3)
def none(obs, t): return None
def text(obs, t): return np.full(obs["state"].shape[:-1] + (2,), "a")
def raises(obs, t): raise ZeroDivisionError("boom")
def ints(obs, t): return np.zeros(obs["state"].shape[:-1] + (2,), int)
def huge(obs, t): return np.full(obs["state"].shape[:-1] + (2,), 1e300)
def as_list(obs, t): return [[0.0, 0.0]] * len(obs["state"])
not_callable = 3
'''


def _files(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".lock"}


def kept(folder: Path):
    """An `after` check: every file in `folder` as it was before the try."""
    before = _files(folder)
    return lambda: (_files(folder) == before, f"{folder.name} changed")


def finite_table(folder: Path, name: str = "per_episode.parquet"):
    def judge(_):
        import numpy as np

        from mjx_pusht.io.outputs import read_table

        t = read_table(folder / name)
        ok = bool(np.isfinite(t["tee_final_x"]).all() and t["finite"].all())
        return ok, f"{len(t['seed'])} rows, all finite: {ok}"

    return judge


def tries(root: Path) -> list[Try]:
    (root / "ctl_hostile.py").write_text(CONTROLLERS)
    sys.path.insert(0, str(root))
    (root / "a_file").write_text("x")
    ev = root / "eval_cpu"
    assert run_cli(["eval", "--backend", "cpu", "--seeds", "3", "--max-steps", "3", "--no-rerun", "--no-progress",
                    "--out", ev])[0] == 0
    twin = root / "eval_twin"  # the same eval marked as run on MJX-Warp: a pairing compare --evals takes
    shutil.copytree(ev, twin)
    s = json.loads((twin / "summary.json").read_text())
    s["backend"] = s["config"]["backend"] = "mjx-warp"
    (twin / "summary.json").write_text(json.dumps(s))
    mine = root / "eval_mine"  # an eval of this user's to be replaced by another eval (the same command)
    shutil.copytree(ev, mine)
    broken = {}
    for name, edit in (("no_field", lambda s: s.pop("controller")), ("no_config_field", lambda s: s["config"].pop("reset")),
                       ("not_json", None), ("a_list", None), ("bad_table", None)):
        d = root / f"eval_{name}"
        shutil.copytree(twin, d)
        if name == "not_json":
            (d / "summary.json").write_text("{not json")
        elif name == "a_list":
            (d / "summary.json").write_text("[1, 2]")
        elif name == "bad_table":
            (d / "per_episode.parquet").write_bytes(b"PAR1 not a table")
        else:
            s = json.loads((d / "summary.json").read_text())
            edit(s)
            (d / "summary.json").write_text(json.dumps(s))
        broken[name] = d
    # an interrupted sweep's folder, then broken in the ways a disk or a hand can break it
    cut = root / "cut"
    assert run_cli(["sweep", "--backend", "cpu", "--seeds", "4", "--steps", "5", "--chunk", "2", "--no-rerun",
                    "--no-progress", "--out", cut])[0] == 0
    parts = {}
    for name in ("manifest", "chunk", "run_file"):
        d = root / f"cut_{name}"
        (d / ".parts").mkdir(parents=True)
        (d / ".run.json").write_text((cut / ".run.json").read_text() if name != "run_file" else "[not, json")
        (d / ".parts" / "manifest.json").write_text("{not json" if name == "manifest" else json.dumps(
            {"config": {"backend": "cpu", "break_it": "none", "steps": 5, "params": []}, "n_seeds": 4,
             "seeds_sha256": __import__("hashlib").sha256(__import__("numpy").arange(4).tobytes()).hexdigest()}))
        (d / ".parts" / "seeds-000000000000-000000000002.parquet").write_bytes(
            b"PAR1 cut short" if name == "chunk" else (cut / "per_seed.parquet").read_bytes())
        parts[name] = d
    o = iter(range(10_000))

    def out() -> str:
        return str(root / f"out{next(o)}")

    def c(surface, *argv, expect="refuse", judge=None, after=None):
        return Try(f"cli {surface}", "", list(argv), expect, judge, after)

    quick = ("--backend", "cpu", "--no-rerun", "--no-progress")
    ev_args = ("eval", *quick, "--seeds", "2", "--max-steps", "3")
    sw_args = ("sweep", *quick, "--seeds", "2", "--steps", "5")
    t = [
        c("", expect="refuse"), c("", "nope"), c("", "--verbose"), c("", "scene", "--bogus"),
        c("", "--help", expect="honour"),
        # scene
        c("scene", "scene", "--seed", "-1"), c("scene", "scene", "--seed", "abc"), c("scene", "scene", "--seed", "1.5"),
        c("scene", "scene", "--seed", str(2**63)), c("scene", "scene", "--steps", "0"),
        c("scene", "scene", "--steps", "-5"), c("scene", "scene", "--steps", "1e3"),
        c("scene", "scene", "--steps", "1000000000", "--no-rerun", "--out", out()),
        c("scene", "scene", "--break", "bogus"), c("scene", "scene", "--compare-welded", "--out", out()),
        c("scene", "scene", "--out", str(root / "a_file")), c("scene", "scene", "--out", "/proc/nope"),
        c("scene", "scene", "--out", "", "--no-rerun"),
        c("scene", "scene", "--seed", "3", "--no-rerun", "--out", out(), expect="honour"),
        c("scene", "scene", "--seed", str(2**63 - 1), "--no-rerun", "--out", out(), expect="honour"),
        c("scene", "scene", "--no-rerun", "--out", ev, after=kept(ev)),
        c("scene", "scene", "--no-rerun", "--replace", "--out", ev, after=kept(ev)),
        # tree
        c("tree", "tree", "--pusher", "box"), c("tree", "tree", "--break", "nope"),
        c("tree", "tree", "--json", expect="honour"), c("tree", "tree", "--colliders", "--break", "free-tee", expect="honour"),
        # sweep
        *[c("sweep", *sw_args[:-4], "--steps", "5", "--seeds", s, "--out", out()) for s in
          ("", " ", "abc", "-5", "0", "5:3", "3:3", "1,2,x", "1,,2", "1,1", str(2**64), "1e3", "0:10000000000000",
           "1:2:3", str(2**63))],
        c("sweep", "sweep", *quick, "--seeds", "2", "--steps", "0"),
        c("sweep", "sweep", *quick, "--seeds", "2", "--steps", "1000000000", "--out", out()),
        c("sweep", *sw_args, "--backend", "bogus", "--out", out()), c("sweep", *sw_args, "--backend", "", "--out", out()),
        c("sweep", *sw_args, "--chunk", "0", "--out", out()), c("sweep", *sw_args, "--chunk", "-1", "--out", out()),
        c("sweep", *sw_args, "--chunk", "x", "--out", out()), c("sweep", *sw_args, "--record", "-1", "--out", out()),
        *[c("sweep", *sw_args, "--param", p, "--out", out()) for p in
          ("bogus=1", "kv=", "kv=abc", "kv=-1", "kv=1e400", "kv=nan", "kv=inf", "tee_mass=0", "tee_mass=-1",
           "kv=1:2:0", "kv=1:2:-3", "kv=1:2:100000000", "=1", "kv", "tee_damping=-0.5", "tee_frictionloss=-1",
           "kv=~1:2:0", "kv=1,,2")],
        c("sweep", *sw_args, "--param", "kv=10", "--param", "kv=20", "--out", out()),
        c("sweep", *sw_args, "--param", "kv=10:30:2", "--out", out(), expect="honour"),
        c("sweep", *sw_args, "--param", "kv=1:2:100", "--param", "tee_mass=0.1:1:100", "--out", out()),
        c("sweep", *sw_args, "--param", "kv=1:2:5000", "--out", out()),
        c("sweep", *sw_args, "--audit", "2", "--out", out()), c("sweep", *sw_args, "--audit", "-0.1", "--out", out()),
        c("sweep", *sw_args, "--audit", "nan", "--out", out()),
        c("sweep", *sw_args, "--num-processes", "0", "--out", out()),
        c("sweep", *sw_args, "--num-processes", "2", "--process-id", "5", "--out", out()),
        c("sweep", *sw_args, "--num-processes", "2", "--out", out()),
        c("sweep", *sw_args, "--num-processes", "2", "--coordinator", "nonsense", "--out", out()),
        c("sweep", *sw_args, "--peer-timeout", "0", "--out", out()),
        c("sweep", *sw_args, "--peer-timeout", "inf", "--out", out()),
        c("sweep", *sw_args, "--resume", "--out", out(), expect="honour"),
        c("sweep", *sw_args, "--out", str(root / "a_file")),
        *[c("sweep", "sweep", *quick, "--seeds", "4", "--steps", "5", "--chunk", "2", "--resume", "--out", d)
          for d in parts.values()],
        c("sweep", "sweep", *quick, "--seeds", "4", "--steps", "5", "--chunk", "2", "--out", parts["manifest"]),
        c("sweep", *sw_args, "--out", ev, after=kept(ev)), c("sweep", *sw_args, "--replace", "--out", ev, after=kept(ev)),
        # eval
        *[c("eval", *ev_args, "--controller", s, "--out", out()) for s in
          ("", "nosuch", "os:getcwd", "ctl_hostile:not_callable", "ctl_hostile:missing", "no_module:x", "policy:",
           "policy:/nonexistent.msgpack", "policy:/etc/passwd", f"policy:{root}", "ctl_hostile:shape",
           "ctl_hostile:none", "ctl_hostile:text", "ctl_hostile:raises", "ctl_hostile:as_list", "ctl_hostile:nan",
           "ctl_hostile:inf_later", "ctl_hostile:neg_inf_one_row")],
        c("eval", *ev_args, "--controller", "ctl_hostile:ints", "--out", (o1 := out()), expect="honour",
          judge=finite_table(Path(o1))),
        c("eval", *ev_args, "--controller", "ctl_hostile:huge", "--out", (o2 := out()), expect="honour",
          judge=finite_table(Path(o2))),
        c("eval", *ev_args, "--action", "bogus", "--out", out()),
        c("eval", *ev_args, "--action", "position", "--controller", "expert", "--out", out()),
        c("eval", *ev_args, "--reset", "bogus", "--out", out()),
        c("eval", "eval", *quick, "--seeds", "2", "--max-steps", "0", "--out", out()),
        c("eval", "eval", *quick, "--seeds", "2", "--max-steps", "-1", "--out", out()),
        c("eval", "eval", *quick, "--seeds", "2", "--max-steps", "1000000000", "--out", out()),
        c("eval", *ev_args, "--frame-skip", "0", "--out", out()),
        c("eval", *ev_args, "--frame-skip", "1000000000", "--out", out()),
        c("eval", *ev_args, "--video", str(root / "v.avi"), "--out", out()),
        c("eval", *ev_args, "--video", "/nonexistent/dir/v.gif", "--out", out()),
        c("eval", *ev_args, "--video", str(root), "--out", out()),
        *[c("eval", *ev_args, "--video", str(root / "v.gif"), "--video-size", s, "--out", out())
          for s in ("0", "31", "100000", "abc")],
        c("eval", *ev_args, "--video", str(root / "v.gif"), "--video-episodes", "0", "--out", out()),
        c("eval", "eval", *quick, "--seeds", "16", "--max-steps", "300", "--video", str(root / "v.gif"),
          "--video-size", "2048", "--out", out()),
        c("eval", *ev_args, "--video", str(root / "ok.gif"), "--video-size", "32", "--out", out(), expect="honour",
          judge=lambda r: ((root / "ok.gif").read_bytes()[:3] == b"GIF", "a GIF written")),
        c("eval", *ev_args, "--break", "free-tee", "--out", out(), expect="honour"),
        c("eval", *ev_args, "--param", "kv=0", "--out", out(), expect="honour"),  # a servo without gain: valid
        c("eval", *ev_args, "--out", ev, after=kept(ev)), c("eval", *ev_args, "--replace", "--out", mine, expect="honour",
          judge=lambda r: (sorted(_files(mine)) == [".run.json", "per_episode.parquet", "summary.json"],
                           "the same command's results replaced, nothing else there")),
        c("eval", *ev_args, "--resume", "--out", ev, after=kept(ev)),
        # compare
        c("compare", "compare", "--backend", "cpu", "--out", out()), c("compare", "compare", "--backend", "bogus", "--out", out()),
        c("compare", "compare", "--seeds", "x", "--out", out()), c("compare", "compare", "--tolerance", "0", "--out", out()),
        c("compare", "compare", "--tolerance", "-1", "--out", out()), c("compare", "compare", "--tolerance", "nan", "--out", out()),
        c("compare", "compare", "--iterations", "0", "--out", out()),
        c("compare", "compare", "--max-steps", "0", "--controller", "expert", "--out", out()),
        c("compare", "compare", "--controller", "nosuch", "--backend", "mjx-warp", "--out", out()),
        c("compare", "compare", "--controller", "ctl_hostile:not_callable", "--backend", "mjx-warp", "--out", out()),
        c("compare", "compare", "--evals", str(ev)), c("compare", "compare", "--evals", str(ev), str(ev), "--out", out()),
        c("compare", "compare", "--evals", str(root / "nope"), str(ev), "--out", out()),
        c("compare", "compare", "--evals", str(root / "a_file"), str(ev), "--out", out()),
        *[c("compare", "compare", "--evals", str(ev), str(d), "--out", out()) for d in broken.values()],
        c("compare", "compare", "--evals", str(ev), str(twin), "--controller", "expert", "--out", out()),
        c("compare", "compare", "--evals", str(ev), str(twin), "--out", ev, after=kept(ev)),
        c("compare", "compare", "--evals", str(ev), str(twin), "--out", twin, "--replace", after=kept(twin)),
        c("compare", "compare", "--evals", str(ev), str(twin), "--out", out(), expect="honour"),
        # train
        *[c("train", "train", "--backend", "cpu", *a, "--no-rerun", "--no-progress", "--out", out()) for a in (
            ("--envs", "0"), ("--iterations", "0"), ("--hidden", ""), ("--hidden", "0"), ("--hidden", "a,b"),
            ("--hidden", "16,-1"), ("--lr", "0"), ("--lr", "nan"), ("--lr", "-1"), ("--lr", "inf"),
            ("--beta-decay", "2"), ("--batch", "0"), ("--obs", "bogus"), ("--algo", "bogus"), ("--algo", "ppo"),
            ("--algo", "ppo", "--keep", "best"), ("--image-batch", "10", "--batch", "5", "--obs", "pixels_agent_pos"),
            ("--image-steps", "10"), ("--max-samples", "0"), ("--minutes", "0"), ("--minutes", "-1"),
            ("--minutes", "nan"), ("--seed", "-1"), ("--resume",), ("--eval-envs", "0"), ("--timesteps", "0"),
            ("--teacher", "bogus"), ("--keep", "bogus"), ("--reset", "bogus"), ("--fit-steps", "0"),
            ("--envs", "1000000000000"), ("--max-samples", "1000000000000"), ("--late-fits", "0"), ("--first-fits", "0"),
            ("--first-fits", "nan"), ("--algo", "ppo", "--backend", "mjx-jax", "--first-fits", "2"),
            ("--max-grad-norm", "0"), ("--max-grad-norm", "nan"), ("--lr-schedule", "bogus"), ("--lr-schedule", "adaptive-kl"),
            ("--algo", "ppo", "--backend", "mjx-jax", "--late-fits", "2"), ("--max-steps", "0"), ("--max-steps", "x"))],
        c("train", "train", "--backend", "cpu", "--no-rerun", "--no-progress", "--out", str(root / "a_file")),
        c("train", "train", "--backend", "cpu", "--envs", "8", "--iterations", "1", "--fit-steps", "5", "--hidden",
          "16", "--eval-envs", "8", "--no-rerun", "--record", "0", "--no-progress", "--out", ev, after=kept(ev)),
    ]
    return t + foreign_files(root, c, ev)


def foreign_files(root: Path, c, ev: Path) -> list[Try]:
    """Issue 57: an --out holding a user's files, at its top and in every folder a command writes its own into
    (data/, meta/, .parts/, eval/, checkpoints/), and outputs/ itself holding other runs: every command, with and
    without --replace, is refused in one line and every file stays (--share-out, said to write beside them, is
    tests/test_foreign_files.py's)."""
    proj, outputs, x = root / "proj", root / "outputs", root / "x"
    for folder, names in ((proj, ("notes.md", "data/mine.txt", "meta/notes.md", ".parts/mine.txt", "eval/mine.txt",
                                  "checkpoints/mine.txt")), (x, (".parts/notes.txt",))):
        for name in names:
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            (folder / name).write_text(f"the user's {name}")
    outputs.mkdir()
    shutil.copytree(ev, outputs / "eval")  # another command's finished results in outputs/
    runs = {"sweep": ("sweep", "--backend", "cpu", "--seeds", "2", "--no-rerun", "--no-progress"),
            "eval": ("eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-rerun", "--no-progress"),
            "scene": ("scene", "--no-rerun"), "compare": ("compare", "--backend", "mjx-warp", "--seeds", "2"),
            "train": ("train", "--backend", "cpu", "--envs", "8", "--iterations", "1", "--no-rerun", "--no-progress"),
            "demos": ("demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "5", "--no-progress")}
    return [c(command, *argv, "--out", str(folder), *extra, after=kept(folder)) for command, argv in runs.items()
            for folder in (proj, outputs, x) for extra in ((), ("--replace",))]
