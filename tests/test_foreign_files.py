"""A command deletes only what it wrote.

`demos --out proj` deleted a user's proj/data/mine.txt and proj/meta/notes.md; `train --out outputs` replaced
outputs/eval, another command's finished results, with its own judgement; `sweep --out x` removed a .parts
folder the user had put in x/; `demos --out ''` wrote into the current folder. Now every command knows the
files it writes (io/outputs: OWN, INSIDE, and the run file it leaves in the folder): an --out holding anything
else is refused in one line unless --share-out is given, a name the command writes (data/, .parts, eval/,
checkpoints/) holding files no run of it wrote is refused whatever the flags, and with or without --replace,
nothing the command did not write is removed.
"""

from __future__ import annotations

import pytest
from helpers import RUNS, one_line, over

from mjx_pusht.cli import main
from mjx_pusht.io.outputs import OutputError, claim_out_dir, held_folders, remove_own

# A user's files where a command might write: at the top, and in each folder some command writes its own into.
USERS = ("notes.md", "data/mine.txt", "meta/notes.md", ".parts/mine.txt", "eval/per_episode.parquet",
         "checkpoints/mine.txt", "sweep/per_seed.parquet")


def tree(folder) -> dict:
    """Every file under `folder` (hidden ones too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def users_files(folder, names=USERS) -> dict:
    for name in names:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(f"the user's {name}")
    return tree(folder)


@pytest.mark.parametrize("command", RUNS)
def test_an_out_holding_a_users_files_is_refused_whatever_the_flags_and_keeps_them(command, tmp_path, capsys):
    out = tmp_path / "outputs"  # outputs/ itself, holding a user's files and other runs' folders
    before = users_files(out)
    for extra in ([], ["--replace"], ["--share-out"], ["--replace", "--share-out"]):
        assert main([*RUNS[command], "--out", str(out), *extra]) == 1
        one_line(capsys, f"--out {out} holds", "never removes")
        assert tree(out) == before  # nothing added: the lock is the kernel's, not a file


@pytest.mark.parametrize("command", RUNS)
def test_a_users_files_beside_a_commands_own_are_refused_unless_shared(command, tmp_path, capsys):
    out = tmp_path / "run"
    before = users_files(out, ["notes.md", "other/mine.txt"])  # no name any command writes
    for extra in ([], ["--replace"]):
        assert main([*RUNS[command], "--out", str(out), *extra]) == 1
        one_line(capsys, f"holds files {command} did not write (notes.md, other/)", "--share-out")
        assert tree(out).items() >= before.items()


@pytest.mark.parametrize(("command", "result", "other"), [("sweep", "per_seed.parquet", ["--seeds", "3"]),
                                                         ("scene", "metrics.json", ["--seed", "1"])])
def test_shared_out_runs_and_reruns_with_replace_beside_the_users_files(command, result, other, tmp_path):
    out = tmp_path / "run"
    before = users_files(out, ["notes.md", "other/mine.txt"])
    assert main([*RUNS[command], "--out", str(out), "--share-out"]) == 0
    first = (out / result).read_bytes()
    assert main(over(RUNS[command], *other, "--out", str(out), "--share-out", "--replace")) == 0
    assert (out / result).read_bytes() != first and tree(out).items() >= before.items()


@pytest.mark.slow
@pytest.mark.parametrize("command", ["demos", "train"])
def test_demos_and_train_keep_a_users_files_beside_their_own(command, tmp_path, capsys):
    out = tmp_path / "run"
    before = users_files(out, ["notes.md", "other/mine.txt"])
    assert main([*RUNS[command], "--out", str(out), "--share-out"]) == 0
    written = tree(out)
    # a second run: its own folders (data/, checkpoints/, eval/) hold a file the user added since: refused
    (out / ("data" if command == "demos" else "checkpoints") / "mine.txt").write_text("added")
    assert main([*RUNS[command], "--out", str(out), "--share-out", "--replace"]) == 1
    one_line(capsys, "which", "never removes")
    assert tree(out).items() >= written.items() and tree(out).items() >= before.items()


def test_the_reported_cases_keep_every_file(tmp_path, capsys, monkeypatch):
    proj = tmp_path / "proj"
    before = users_files(proj, ["data/mine.txt", "meta/notes.md"])
    assert main([*RUNS["demos"], "--out", str(proj)]) == 1
    one_line(capsys, "holds data, meta, which demos writes but no demos run wrote here")
    x = tmp_path / "x"
    users_files(x, [".parts/notes.txt"])
    assert main([*RUNS["sweep"], "--out", str(x), "--replace"]) == 1
    one_line(capsys, "holds .parts, which sweep writes")
    assert (x / ".parts" / "notes.txt").exists() and tree(proj).items() >= before.items()
    outputs = tmp_path / "outputs"
    assert main([*RUNS["eval"], "--out", str(outputs / "eval")]) == 0
    finished = tree(outputs / "eval")
    capsys.readouterr()
    assert main([*RUNS["train"], "--out", str(outputs)]) == 1
    one_line(capsys, "holds eval, which train writes but no train run wrote here")
    assert tree(outputs / "eval") == finished
    monkeypatch.chdir(tmp_path)
    assert main([*RUNS["demos"], "--out", ""]) == 2
    one_line(capsys, "--out: is empty")
    with pytest.raises(OutputError, match="--out is empty"):  # the library refuses it too
        claim_out_dir("", "demos", {})


def test_replace_removes_the_commands_own_files_and_nothing_in_its_folders_it_did_not_write(tmp_path):
    out = tmp_path / "sw"
    with held_folders():
        claim_out_dir(out, "sweep", {"seeds": 1})
    (out / ".parts").mkdir()
    (out / "per_seed.parquet").write_text("table")
    (out / ".parts" / "seeds-000000000000-000000000002.parquet").write_text("chunk")
    (out / ".parts" / "mine.txt").write_text("the user's")
    with held_folders(), pytest.raises(OutputError, match=r"holds .parts/mine.txt, which sweep writes"):
        claim_out_dir(out, "sweep", {"seeds": 2}, replace=True, share=True)
    assert (out / "per_seed.parquet").exists()
    remove_own(out / ".parts")  # what a finished sweep does with its chunks: the user's file stays
    assert sorted(p.name for p in (out / ".parts").iterdir()) == ["mine.txt"]


# Bad input found only after the folder is claimed: the backend or env refuses the run (found by a newcomer's pass)
REFUSED_AFTER_CLAIM = {
    "eval": ("eval", "--backend", "gym-pusht", "--seeds", "2", "--no-rerun"),  # the chapter task on gym-pusht
    "sweep": ("sweep", "--backend", "gym-pusht", "--seeds", "2", "--no-rerun"),
    "train": ("train", "--task", "gym-pusht", "--backend", "gym-pusht", "--no-rerun"),  # creates checkpoints/ first
    "demos": ("demos", "--controller", "zero", "--successful-only", "--backend", "cpu", "--seeds", "2",
              "--max-steps", "3", "--no-progress"),  # nothing succeeds
}


@pytest.mark.parametrize("command", REFUSED_AFTER_CLAIM)
def test_a_run_refused_after_its_claim_leaves_no_folder_it_made_and_keeps_one_it_did_not(command, tmp_path, capsys):
    out = tmp_path / "new" / "run"
    assert main([*REFUSED_AFTER_CLAIM[command], "--out", str(out)]) == 1
    one_line(capsys, "mjx-pusht: error:")
    assert not (tmp_path / "new").exists()  # neither --out nor the folder made above it
    before = users_files(out, ["notes.md"])
    assert main([*REFUSED_AFTER_CLAIM[command], "--out", str(out), "--share-out"]) == 1
    one_line(capsys, "mjx-pusht: error:")
    assert tree(out).items() >= before.items()
