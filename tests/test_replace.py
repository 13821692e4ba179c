"""--replace replaces the same command's own results, and nothing else.

`eval --out RUN --replace --controller policy:RUN/policy.msgpack` into a finished train folder deleted the policy
it had just evaluated and the train's summary.json; `compare --evals A B --out A --replace` deleted A's table. A
folder holding another command's results is now refused whatever the flags, in one line naming what is there,
and every file in it stays as it was.
"""

from __future__ import annotations

import json
import shutil

import pytest
from helpers import cli

TINY_TRAIN = ("--backend", "cpu", "--envs", "8", "--iterations", "1", "--fit-steps", "5", "--hidden", "16",
              "--eval-envs", "8", "--no-rerun", "--record", "0", "--no-progress")
EVAL = ("eval", "--backend", "cpu", "--max-steps", "3", "--no-rerun", "--no-progress")


def tree(folder) -> dict:
    """Every file under `folder` (recursively, hidden ones too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def refused(r, *words) -> str:
    assert r.returncode == 1, (r.returncode, r.stdout[-500:], r.stderr[-500:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert all(w in lines[0] for w in words), lines[0]
    return lines[0]


@pytest.mark.slow
def test_eval_and_sweep_into_a_train_folder_are_refused_with_or_without_replace_and_keep_every_file(tmp_path):
    run = tmp_path / "run"
    assert cli("train", *TINY_TRAIN, "--out", str(run)).returncode == 0
    before = tree(run)
    assert {"policy.msgpack", "summary.json", "curve.csv", "eval/per_episode.parquet"} <= set(before)
    for extra in ([], ["--replace"]):
        r = cli(*EVAL, "--seeds", "2", "--controller", f"policy:{run / 'policy.msgpack'}", "--out", str(run), *extra)
        refused(r, "holds train's results", "policy.msgpack", "whatever the flags")
        r = cli("sweep", "--backend", "cpu", "--seeds", "2", "--no-rerun", "--no-progress", "--out", str(run), *extra)
        refused(r, "holds train's results", "policy.msgpack")
        # the train's own judgement (run/eval) is the train's: an eval --replace there would overwrite it
        r = cli(*EVAL, "--seeds", "3", "--controller", f"policy:{run / 'policy.msgpack'}", "--out", str(run / "eval"),
                *extra)
        refused(r, "inside the train run", "never writes into another run's folder")
        assert tree(run) == before
    # the policy is still there to evaluate, elsewhere
    r = cli(*EVAL, "--seeds", "2", "--controller", f"policy:{run / 'policy.msgpack'}", "--out", str(tmp_path / "e"))
    assert r.returncode == 0, r.stderr[-500:]


@pytest.fixture(scope="module")
def two_evals(tmp_path_factory):
    """A finished cpu eval and its twin marked as run on MJX-Warp (what compare --evals pairs)."""
    root = tmp_path_factory.mktemp("evals")
    a, b = root / "a", root / "b"
    assert cli(*EVAL, "--seeds", "3", "--out", str(a)).returncode == 0
    shutil.copytree(a, b)
    s = json.loads((b / "summary.json").read_text())
    s["backend"] = s["config"]["backend"] = "mjx-warp"
    (b / "summary.json").write_text(json.dumps(s))
    return a, b


def test_compare_evals_onto_one_of_its_own_evals_is_refused_and_keeps_it(two_evals, tmp_path):
    a, b = two_evals
    for out in (a, b):
        before = tree(out)
        for extra in ([], ["--replace"]):
            r = cli("compare", "--evals", str(a), str(b), "--out", str(out), *extra)
            refused(r, "holds eval's results", "per_episode.parquet", "summary.json")
            assert tree(out) == before
    r = cli("compare", "--evals", str(a), str(b), "--out", str(tmp_path / "c"))  # the pairing itself is fine
    assert r.returncode == 0 and (tmp_path / "c" / "compare_episodes.json").exists(), r.stderr[-500:]


@pytest.mark.slow
def test_replace_removes_the_same_commands_own_files_only(tmp_path):
    out = tmp_path / "e"
    assert cli(*EVAL, "--seeds", "2", "--out", str(out)).returncode == 0
    (out / "notes.txt").write_text("mine")
    for extra in ([], ["--replace"]):  # a user's file beside the results: --share-out says to leave it be
        refused(cli(*EVAL, "--seeds", "3", "--out", str(out), *extra), "holds files eval did not write (notes.txt)")
    refused(cli(*EVAL, "--seeds", "3", "--out", str(out), "--share-out"), "other seeds' or settings'", "--replace")
    r = cli(*EVAL, "--seeds", "3", "--out", str(out), "--replace", "--share-out")
    assert r.returncode == 0, r.stderr[-500:]
    assert (out / "notes.txt").read_text() == "mine"
    from mjx_pusht.io.outputs import read_table

    assert list(read_table(out / "per_episode.parquet")["seed"]) == [0, 1, 2]


def test_a_folder_mixing_one_commands_results_with_anothers_is_refused(tmp_path):
    # a policy copied into an eval's folder: eval --replace there would have deleted it
    out = tmp_path / "e"
    assert cli(*EVAL, "--seeds", "2", "--out", str(out)).returncode == 0
    (out / "policy.msgpack").write_bytes(b"weights")
    r = cli(*EVAL, "--seeds", "3", "--out", str(out), "--replace")
    refused(r, "holds files eval does not write (policy.msgpack)")
    assert (out / "policy.msgpack").read_bytes() == b"weights"


def test_a_run_never_replaces_a_file_it_reads(tmp_path):
    from mjx_pusht.io.outputs import OutputError, claim_out_dir, held_folders

    out = tmp_path / "e"
    with held_folders():
        claim_out_dir(out, "eval", {"seeds": 1})
    (out / "summary.json").write_text("{}")
    with held_folders(), pytest.raises(OutputError, match="reads .*summary.json, which its own results would replace"):
        claim_out_dir(out, "eval", {"seeds": 2}, replace=True, reads=[out / "summary.json"])
    assert (out / "summary.json").read_text() == "{}"
