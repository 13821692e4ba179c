"""LeRobot's dataset format (v3.0, as lerobot 0.6.1 reads it from `--dataset.root`), written without lerobot.

lerobot 0.6.1 installs on Python >= 3.12 only, and this project runs on 3.11 too, so the writer
makes the files itself, laid out and typed as LeRobotDataset's own writer lays them out for
image features (tests/lerobot/ reads them back with lerobot 0.6.1 and trains on them):

    meta/info.json                          codebase_version v3.0, fps, features, totals, paths
    meta/stats.json                         min, max, mean, std, count, q01 .. q99 of every feature
    meta/tasks.parquet                      task_index, indexed by the task's text (pandas' index)
    meta/episodes/chunk-000/file-000.parquet  one row an episode: length, its rows in the data files
    data/chunk-CCC/file-FFF.parquet         one row a frame; images as PNG bytes in the row

A frame is (the observation before the action, the action, what the step gave): `next.reward`,
`next.done`, `next.success`, as lerobot-eval records episodes. Per-episode statistics columns
(`stats/...` in meta/episodes), which LeRobotDataset drops on loading, are not written. The image
statistics are of a sample of frames (as LeRobot's own are): those the caller counts into
`image_histogram`, every 10th frame of an episode in `io.demos`.
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from pathlib import Path

import numpy as np

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000  # files per chunk folder, as LeRobot's writer names them
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
INDEX_FEATURES = ("timestamp", "frame_index", "episode_index", "index", "task_index")


def pusht_features(image_size: int = 96) -> dict:
    """The features of LeRobot's `lerobot/pusht` (observation.image, observation.state, action and the step's
    outcome), images stored as images; then the index columns every LeRobot dataset has."""
    xy = {"motors": ["x", "y"]}
    one = {"shape": [1], "names": None}
    return {
        "observation.image": {"dtype": "image", "shape": [image_size, image_size, 3],
                              "names": ["height", "width", "channel"]},
        "observation.state": {"dtype": "float32", "shape": [2], "names": xy},
        "action": {"dtype": "float32", "shape": [2], "names": xy},
        "next.reward": {"dtype": "float32", **one},
        "next.done": {"dtype": "bool", **one},
        "next.success": {"dtype": "bool", **one},
        "timestamp": {"dtype": "float32", **one},
        **{k: {"dtype": "int64", **one} for k in INDEX_FEATURES[1:]},
    }


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def histogram(images: np.ndarray) -> np.ndarray:
    """(3, 256) counts of each byte value per channel in (..., 3) uint8 images."""
    return np.stack([np.bincount(images[..., c].ravel(), minlength=256) for c in range(3)])


def png(image: np.ndarray) -> bytes:
    """An (H, W, 3) uint8 image as a PNG file: filter 0 rows, zlib level 1 (7x faster than Pillow's encoder
    for a 96 x 96 image; zlib releases the GIL, so threads encode in parallel). Lossless: it decodes to `image`."""
    h, w, _ = image.shape
    raw = np.empty((h, w * 3 + 1), np.uint8)
    raw[:, 0] = 0
    raw[:, 1:] = image.reshape(h, w * 3)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + _chunk(b"IDAT", zlib.compress(raw.tobytes(), 1)) + _chunk(b"IEND", b""))


def _hf_type(ft: dict) -> dict:
    """The Hugging Face `datasets` feature of a LeRobot feature, as LeRobot's writer records it."""
    if ft["dtype"] == "image":
        return {"_type": "Image"}
    if ft["shape"] == [1]:
        return {"dtype": ft["dtype"], "_type": "Value"}
    return {"feature": {"dtype": ft["dtype"], "_type": "Value"}, "length": ft["shape"][0], "_type": "List"}


def _numeric_stats(x: np.ndarray) -> dict:
    x = np.asarray(x, np.float64).reshape(len(x), -1)
    out = {"min": x.min(0), "max": x.max(0), "mean": x.mean(0), "std": x.std(0), "count": np.array([len(x)])}
    for q, v in zip(QUANTILES, np.quantile(x, QUANTILES, axis=0), strict=True):
        out[f"q{round(q * 100):02d}"] = v
    return {k: v.tolist() for k, v in out.items()}


def _image_stats(hist: np.ndarray, frames: int) -> dict:
    """Per-channel statistics of images scaled to [0, 1] (shape (3, 1, 1), as LeRobot keeps them), exact from
    the (3, 256) histogram of byte values; quantiles are the lowest value whose cumulative share reaches q."""
    v = np.arange(256) / 255.0
    n = hist.sum(1)
    mean = hist @ v / n
    std = np.sqrt(np.maximum(hist @ (v * v) / n - mean**2, 0.0))
    cdf = np.cumsum(hist, 1) / n[:, None]
    out = {"min": np.array([v[np.flatnonzero(h)[0]] for h in hist]), "max": np.array([v[np.flatnonzero(h)[-1]] for h in hist]),
           "mean": mean, "std": std}
    out = {k: a.reshape(3, 1, 1).tolist() for k, a in out.items()}
    out["count"] = [int(frames)]
    for q in QUANTILES:
        out[f"q{round(q * 100):02d}"] = np.array([v[np.argmax(c >= q)] for c in cdf]).reshape(3, 1, 1).tolist()
    return out


def _write_parquet(table, path: Path) -> None:
    import pyarrow.parquet as pq

    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path)


class LeRobotDatasetWriter:
    """Writes episodes into `root` as a LeRobot v3.0 dataset: `add` a batch of finished episodes (one data
    file), then `finish` (metadata last, so a folder without meta/info.json is no dataset)."""

    def __init__(self, root: Path, fps: int, task: str, image_size: int = 96):
        self.root, self.fps, self.task = Path(root), int(fps), task
        self.features = pusht_features(image_size)
        self.episodes: list[dict] = []
        self.frames = 0
        self.files = 0
        self._numeric: dict[str, list] = {k: [] for k, f in self.features.items() if f["dtype"] != "image"}
        self.image_histogram = np.zeros((3, 256), np.int64)  # the image statistics' sample, counted by the caller
        self.image_frames = 0  # frames in that sample

    def add(self, episodes: list[dict]) -> None:
        """Episodes, each a dict of per-frame values: png (T PNG files, `png`), state (T, 2), action (T, 2),
        reward (T,), done (T,), success (T,); written as one data file."""
        import pyarrow as pa

        if not episodes:
            return
        pngs = [b for ep in episodes for b in ep["png"]]
        lengths = [len(ep["action"]) for ep in episodes]
        n = sum(lengths)
        cols = {
            "observation.state": np.concatenate([ep["state"] for ep in episodes]).astype(np.float32),
            "action": np.concatenate([ep["action"] for ep in episodes]).astype(np.float32),
            "next.reward": np.concatenate([ep["reward"] for ep in episodes]).astype(np.float32),
            "next.done": np.concatenate([ep["done"] for ep in episodes]).astype(bool),
            "next.success": np.concatenate([ep["success"] for ep in episodes]).astype(bool),
            "frame_index": np.concatenate([np.arange(t, dtype=np.int64) for t in lengths]),
            "episode_index": np.repeat(np.arange(len(self.episodes), len(self.episodes) + len(episodes)), lengths),
            "index": np.arange(self.frames, self.frames + n, dtype=np.int64),
            "task_index": np.zeros(n, np.int64),
        }
        cols["timestamp"] = (cols["frame_index"] / self.fps).astype(np.float32)
        for k in self._numeric:
            self._numeric[k].append(cols[k])
        chunk, file = divmod(self.files, CHUNKS_SIZE)
        arrays, fields = [], []
        for key, ft in self.features.items():
            if ft["dtype"] == "image":
                arr = pa.StructArray.from_arrays([pa.array(pngs, pa.binary()), pa.nulls(n, pa.string())],
                                                 names=["bytes", "path"])
            elif ft["shape"] == [1]:
                arr = pa.array(cols[key])
            else:
                arr = pa.FixedSizeListArray.from_arrays(pa.array(cols[key].ravel()), ft["shape"][0])
            arrays.append(arr)
            fields.append(pa.field(key, arr.type))
        hf = {"info": {"features": {k: _hf_type(f) for k, f in self.features.items()}}}
        schema = pa.schema(fields, metadata={"huggingface": json.dumps(hf)})
        _write_parquet(pa.Table.from_arrays(arrays, schema=schema), self.root / DATA_PATH.format(chunk_index=chunk,
                                                                                                 file_index=file))
        start = self.frames
        for t in lengths:
            self.episodes.append({"length": t, "chunk": chunk, "file": file, "from": start, "to": start + t})
            start += t
        self.frames += n
        self.files += 1

    def finish(self) -> dict:
        """meta/: episodes, tasks, stats, then info.json. Returns the info."""
        import pyarrow as pa

        e = self.episodes
        ints = lambda key: pa.array([x[key] for x in e], pa.int64())  # noqa: E731
        episodes = pa.table({
            "episode_index": pa.array(np.arange(len(e)), pa.int64()),
            "tasks": pa.array([[self.task]] * len(e), pa.list_(pa.string())),
            "length": ints("length"), "data/chunk_index": ints("chunk"), "data/file_index": ints("file"),
            "dataset_from_index": ints("from"), "dataset_to_index": ints("to"),
            "meta/episodes/chunk_index": pa.array(np.zeros(len(e)), pa.int64()),
            "meta/episodes/file_index": pa.array(np.zeros(len(e)), pa.int64()),
        })
        _write_parquet(episodes, self.root / EPISODES_PATH)
        # pandas' index metadata: LeRobot reads tasks with pandas and looks tasks up by their text
        pandas_meta = {"index_columns": ["task"], "column_indexes": [
            {"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object",
             "metadata": {"encoding": "UTF-8"}}], "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
             "metadata": None},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": None}],
            "attributes": {}, "creator": {"library": "pyarrow", "version": pa.__version__}}
        tasks = pa.table({"task_index": pa.array([0], pa.int64()), "task": pa.array([self.task], pa.string())})
        _write_parquet(tasks.replace_schema_metadata({"pandas": json.dumps(pandas_meta)}), self.root / "meta/tasks.parquet")
        stats = {k: _numeric_stats(np.concatenate(v)) for k, v in self._numeric.items()}
        stats["observation.image"] = _image_stats(self.image_histogram, self.image_frames)
        _write_json(self.root / "meta/stats.json", stats)
        info = {
            "codebase_version": CODEBASE_VERSION, "fps": self.fps, "features": self.features,
            "total_episodes": len(e), "total_frames": self.frames, "total_tasks": 1, "chunks_size": CHUNKS_SIZE,
            "data_files_size_in_mb": 100, "video_files_size_in_mb": 200, "data_path": DATA_PATH, "video_path": None,
            "robot_type": None, "splits": {"train": f"0:{len(e)}"},
        }
        _write_json(self.root / "meta/info.json", info)
        return info


def _write_json(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(obj, indent=4) + "\n")
    os.replace(tmp, path)
