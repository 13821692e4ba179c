"""Videos of episodes: a grid of tiles, one episode each, at the control rate, coverage written on every tile.

Frames come from a rollout's trace (qpos every physics step, whatever backend made it) and are
drawn by the CPU renderer (pixels.py), so a video looks like the pixel observations a policy
sees. GIFs need only Pillow; MP4 needs imageio with its ffmpeg (`pip install 'mjx-pusht[video]'`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from mjx_pusht.errors import MjxPushtError, needs
from mjx_pusht.task.rules import coverage_np

FORMATS = (".gif", ".mp4")


class VideoError(MjxPushtError, RuntimeError):
    """A video that cannot be written (format, missing encoder, unwritable path): one line."""


def check_path(path: Path, replace: bool = False, out: Path | None = None) -> Path:
    """Fail before any work if the video could not be written, or would overwrite a file without `replace`
    saying to. `replace` overwrites only the video this command's earlier run into `out` wrote (its summary names
    the file and its bytes' hash): a file no run wrote is a user's and refused, as `--out` refuses them. A new
    name inside another run's folder (one holding a run file, at any depth) is refused: only that run writes there. (Without `out`,
    as the writer checks again once the frames are drawn, neither of those.)"""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise VideoError(f"--video must end in .gif or .mp4, got {path.name!r}")
    if path.suffix.lower() == ".mp4":
        needs("an MP4 video (a .gif needs nothing more)", "video")
    parent = path.parent if str(path.parent) else Path(".")
    in_out = out is not None and parent.resolve() == Path(out).resolve()  # a new --out: the run makes it
    if not parent.is_dir() and not in_out:
        raise VideoError(f"cannot write the video: folder {parent} does not exist")
    if path.is_dir():
        raise VideoError(f"--video {path} is a folder; give a file name such as {path / 'episodes'}{path.suffix}")
    # a user's file first: "pass --replace" is said only where --replace would overwrite it (the tenth pass)
    if out is not None and os.path.lexists(path) and not wrote(out, path):
        raise VideoError(f"--video {path} already exists and no earlier eval into {out} wrote it; a file no run "
                         "wrote is never overwritten, whatever the flags: give another name")
    if os.path.lexists(path) and not replace:
        raise VideoError(f"--video {path} already exists; pass --replace to overwrite it, or give another name")
    from mjx_pusht.io.own import RUN_FILE, runs_holding

    run = next(runs_holding(parent.resolve()), None) if out is not None else None
    if run is not None and run[0] != Path(out).resolve():  # at any depth: a new name under a finished eval's folder
        raise VideoError(f"--video {path} is inside another run's folder ({run[0]} holds its {RUN_FILE}); a run "
                         "never writes into another run's folder, whatever the flags: give another name")
    if not parent.is_dir():  # --out, made writable by its claim (which refuses one that is not)
        return path
    try:  # the folder must take a new file now, not after the episodes have run
        import tempfile

        with tempfile.NamedTemporaryFile(dir=parent, prefix=".probe-"):
            pass
    except OSError as e:
        raise VideoError(f"cannot write the video into {parent}: {e.strerror or e}") from None
    return path


def stamp(path: Path) -> dict:
    """What a summary records of the video it wrote: its path and its bytes' hash (`wrote` checks both)."""
    import hashlib

    return {"path": str(Path(path).resolve()), "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()}


def wrote(out: Path, path: Path) -> bool:
    """Whether the eval whose summary is in `out` wrote the very file at `path` (not a symlink, unchanged since)."""
    import json

    try:
        video = json.loads((Path(out) / "summary.json").read_text())["video"]
        return (not os.path.islink(path) and video["path"] == str(Path(path).resolve())
                and stamp(path)["sha256"] == video["sha256"])
    except (OSError, ValueError, KeyError, TypeError):
        return False


def earlier(out: Path, aside: bool = False) -> list[Path]:
    """The video an earlier eval drew inside `out` (its summary's stamp names it, unchanged since), or (`aside`) the
    one a --replace that was interrupted set aside with its results in `.replaced/`: the eval's own files, not
    strays (a --replace rerun without --video was refused for its own video: the thirteenth pass)."""
    import json

    from mjx_pusht.io.replace import ASIDE

    out, found = Path(out), []
    for folder in (out / ASIDE,) if aside else (out,):
        try:
            video = json.loads((folder / "summary.json").read_text())["video"]
            rel = Path(video["path"]).relative_to(out.resolve())
        except (OSError, ValueError, KeyError, TypeError):
            continue
        p = folder / rel
        if p.is_file() and not p.is_symlink() and stamp(p)["sha256"] == video["sha256"]:
            found.append(p)
    return found


MAX_FRAME_BYTES = 4 << 30  # every frame is held in memory before it is encoded


def check_grid(size: int, episodes: int, max_steps: int) -> None:
    """Fail before any work if the video's tiles could not be drawn: a tile side the renderer takes, and all the
    frames (one a control step, at most `max_steps` + 1) within MAX_FRAME_BYTES."""
    if int(size) != size or not 32 <= size <= 2048:
        raise VideoError(f"--video-size must be an integer from 32 to 2048 pixels, got {size}")
    cols = math.ceil(math.sqrt(episodes))
    rows = math.ceil(episodes / cols)
    need = (max_steps + 1) * rows * size * cols * size * 3
    if need > MAX_FRAME_BYTES:
        raise VideoError(f"--video-size {size} with {episodes} episodes of up to {max_steps} steps needs "
                         f"{need / 2**30:.1f} GiB of frames (at most {MAX_FRAME_BYTES / 2**30:.0f}): give a smaller "
                         "--video-size, fewer --video-episodes or --max-steps")


def _label(tile: np.ndarray, text: str, success: bool) -> np.ndarray:
    """`text` across the tile's top, whole: its font shrinks until the widest line fits the tile (a held-out seed,
    `seed 1000000000  coverage 0.95`, was cut off at 128 px), and below MIN_LABEL_PX[0] its parts (split at two
    spaces) go one to a line."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(tile)
    draw = ImageDraw.Draw(img)
    room = tile.shape[1] - 6
    lines, size = [text], max(10, tile.shape[0] // 11)
    while True:
        font = _font(size)
        if max(draw.textlength(line, font=font) for line in lines) <= room or font is None:
            break
        if size > MIN_LABEL_PX[len(lines) > 1]:
            size -= 1
        elif len(lines) == 1:
            lines, size = text.split("  "), max(10, tile.shape[0] // 11)
        else:
            break  # too narrow for even one part a line (a 32-pixel tile): cut, as it must be
    draw.rectangle([0, 0, tile.shape[1], len(lines) * (size + 2) + 2], fill=(255, 255, 255))
    for k, line in enumerate(lines):
        draw.text((3, 1 + k * (size + 2)), line, fill=(20, 120, 40) if success else (40, 40, 40), font=font)
    return np.asarray(img)


# The smallest font of a label on one line (smaller, it takes one line a part: at 128 px a held-out seed's label is two
# lines at 11 px, not one at 7), and on several (a held-out seed's `seed 1000000000` fits a 64-pixel tile at 7 px)
MIN_LABEL_PX = (8, 6)


def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 has one bitmap font, of one size
        return None


def episode_grid(model, qpos: np.ndarray, layout, seeds, frame_skip: int, success: float,
                 size: int = 128, goals=None) -> np.ndarray:
    """(frames, H, W, 3) uint8: episode i of the traced qpos (K, 1 + steps, nq) in tile i of a near-square grid,
    one frame per control step, each tile labelled with its seed and coverage. `goals` (K, 3): each episode's
    random goal, where its target is drawn and its coverage measured (None: the scene's target)."""
    from mjx_pusht.render.pixels import CpuRenderer

    k, t = qpos.shape[0], qpos.shape[1]
    idx = np.arange(0, t, frame_skip)
    cols = math.ceil(math.sqrt(k))
    rows = math.ceil(k / cols)
    renderer = CpuRenderer(model, size)
    try:
        frames = np.full((len(idx), rows * size, cols * size, 3), 255, np.uint8)
        for i in range(k):
            q = qpos[i, idx]
            goal = None if goals is None else goals[i]
            cov = coverage_np(layout.tee_pose(q)) if goal is None else coverage_np(layout.tee_pose(q), goal)
            tiles = renderer(q, goal)
            r, c = divmod(i, cols)
            for f in range(len(idx)):
                text = f"seed {seeds[i]}  coverage {cov[f]:.2f}"  # green once the episode has succeeded
                frames[f, r * size:(r + 1) * size, c * size:(c + 1) * size] = _label(tiles[f], text, cov[f] >= success)
    finally:
        renderer.close()
    # thin white lines between tiles
    for c in range(1, cols):
        frames[:, :, c * size - 1] = 255
    for r in range(1, rows):
        frames[:, r * size - 1] = 255
    return frames


def write(path: Path, frames: np.ndarray, fps: float) -> None:
    """GIF through Pillow, MP4 through imageio's ffmpeg; written to a temporary name, then moved into place."""
    path = check_path(path, replace=True)  # whether it may overwrite was checked before the episodes ran
    tmp = path.with_name("." + path.name + ".partial" + path.suffix)  # hidden until whole, as record.py's
    try:
        _encode(tmp, path, frames, fps)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _encode(tmp: Path, path: Path, frames: np.ndarray, fps: float) -> None:
    if path.suffix.lower() == ".gif":
        from PIL import Image

        imgs = [Image.fromarray(f) for f in frames]
        imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=round(1000 / fps), loop=0, optimize=False)
    else:
        import warnings

        import imageio.v3 as iio

        even = frames[:, : frames.shape[1] // 2 * 2, : frames.shape[2] // 2 * 2]  # yuv420p wants even sizes
        with warnings.catch_warnings():
            # imageio starts ffmpeg with subprocess, a fork that execs at once: JAX's warning about forking
            # a multithreaded process is for children that go on running Python, which this one never does
            warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
            iio.imwrite(tmp, even, fps=fps, codec="libx264", plugin="pyav" if _has_pyav() else None)


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401

        return True
    except ImportError:
        return False
