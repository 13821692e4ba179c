"""tools/offline-gpu/carry_run.sh: a run's state cut into parts on one host and put back, byte for byte, on the next.

The run here is a stand-in LeRobot output folder (two checkpoints, `last` naming the newer, a log): what is tested is
the tool, not LeRobot (tests/lerobot/ carries a real run through benchmarks/diffusion_pusht.sh, which runs this tool)."""

from __future__ import annotations

import hashlib
import os
import subprocess
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TOOL = ROOT / "tools" / "offline-gpu" / "carry_run.sh"


def _carry(env: dict, *stages: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(TOOL), *stages], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={**os.environ, **env})


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def test_a_packed_run_comes_back_byte_for_byte_and_a_missing_part_is_one_line_with_nothing_unpacked(tmp_path):
    runs, out, carried = tmp_path / "there", tmp_path / "out", tmp_path / "carried"
    ckpt = runs / "train-7" / "checkpoints"
    weights = np.random.default_rng(0).integers(0, 256, 40 * 2**20, dtype=np.uint8).tobytes()  # 3 parts of 15 MiB
    for step, body in (("000002", b"old"), ("000004", weights)):
        (ckpt / step / "pretrained_model").mkdir(parents=True)
        (ckpt / step / "pretrained_model" / "model.safetensors").write_bytes(body)
    (ckpt / "last").symlink_to("000004")
    (runs / "logs").mkdir()
    (runs / "logs" / "train-7.log").write_text("step:4 loss:0.1\n")
    env = {"RUNS": str(runs), "OUT": str(out), "CARRIED": str(carried)}

    assert _carry(env, "pack-7").returncode == 0
    parts = sorted((runs / "pack").glob("train-7.tar.part.*"))
    assert len(parts) == 3 and all(p.stat().st_size <= 15 * 2**20 for p in parts)
    sent = _carry(env, "send")  # at most 4 parts a call: all 3 now, none the second time
    assert sent.returncode == 0 and sorted(p.name for p in (out / "parts").iterdir()) == sorted(
        [*(p.name for p in parts), "train-7.sha256"])
    assert "every part was sent already" in _carry(env, "send").stdout

    carried.mkdir()
    for p in (out / "parts").iterdir():
        if p.name != parts[0].name:  # the first part lost on the way
            (carried / p.name).write_bytes(p.read_bytes())
    here = tmp_path / "here"
    lost = _carry({**env, "RUNS": str(here)}, "unpack-7")
    assert lost.returncode == 1 and lost.stderr.strip().count("\n") == 0
    assert lost.stderr.startswith("unpack-7: parts missing or damaged") and not (here / "train-7").exists()

    (carried / parts[0].name).write_bytes(parts[0].read_bytes())
    assert _carry({**env, "RUNS": str(here)}, "unpack-7").returncode == 0
    back = here / "train-7" / "checkpoints"
    assert sorted(p.name for p in back.iterdir()) == ["000004", "last"]  # the last checkpoint only, as --resume reads
    assert os.readlink(back / "last") == "000004"
    assert _digest(back / "000004") == _digest(ckpt / "000004")
    assert (here / "logs" / "train-7.log").read_text() == "step:4 loss:0.1\n"


def test_an_unknown_stage_or_pack_mode_is_one_line_and_exit_2(tmp_path):
    env = {"RUNS": str(tmp_path / "r"), "OUT": str(tmp_path / "o")}
    for extra, stage, line in (({}, "bogus", "unknown stage bogus (pack-N send unpack-N)"),
                               ({"PACK": "all"}, "pack-1", "PACK must be resume, model or live, got 'all'")):
        p = _carry({**env, **extra}, stage)
        assert p.returncode == 2 and p.stderr.strip() == line
    assert not (tmp_path / "r").exists()
