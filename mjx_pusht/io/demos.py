"""Demonstrations for LeRobot: a controller's episodes on the gym-pusht drop-in, written as a LeRobot dataset.

    write_demos("expert", seeds=np.arange(1000), out=Path("outputs/demos"))
    lerobot-train --dataset.repo_id=local/mjx_pusht_demos --dataset.root=outputs/demos --policy.type=diffusion ...

The episodes run on the drop-in's vector env (`mjx_pusht/PushT-gym-pusht-v0`, the batch on the GPU
where there is one), and what is written is what a LeRobot user of gym-pusht records: the 96 x 96
image and `agent_pos` before each action, the action in gym-pusht's units (an absolute target in
pixels), and the step's reward, done and success. The env is stepped with the action exactly as
written (float32 pixels), so replaying an episode's actions in the drop-in reproduces its states.

The episodes are gym-pusht's task (task/tasks.py), and `expert` is its expert. The controllers are this
project's (world frame, metres), run as that task runs them (`Task.controller`): a target as it is, a velocity
command v as the target a PD-tracked pusher settles to that velocity with, pusher + (kv / kp) v (gym-pusht's
law, kp 100, kv 20), a position action (`--action position`) as the target itself. With `successful_only`
the dataset keeps the episodes that succeeded (what LeRobot users train on); the summary counts both.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.io.lerobot_dataset import LeRobotDatasetWriter
from mjx_pusht.model import gym_pusht as frame

FPS = 10  # gym-pusht's control rate
TASK = "Push the T-shaped block onto the T-shaped target."  # the task text of LeRobot's lerobot/pusht
IMAGE_SIZE = 96
SAMPLE = 10  # every 10th frame of an episode goes into the image statistics (LeRobot samples its own too)


def targets_px(ctrl, carry, obs_px: dict, info: dict, t: int, key):
    """The controller's actions (targets in metres: `Task.controller`) for a batch as gym-pusht targets (float32
    pixels), and its next carry."""
    from mjx_pusht.task.rules import observe

    pusher = frame.to_world(np.asarray(info["pos_agent"], np.float64))
    pose = np.asarray(info["block_pose"], np.float64)
    tee = frame.pose_to_world(pose[:, 0:2], pose[:, 2])
    obs = observe(pusher, tee)
    action, carry = ctrl.act(carry, obs, t, key)
    with np.errstate(invalid="ignore", over="ignore"):  # a non-finite action: said below, in one line
        px = frame.to_px(np.asarray(action, np.float64))
    # a non-finite action is the controller's bug: said, never recorded as a pusher standing still
    if not np.isfinite(px).all():
        rows = np.flatnonzero(~np.isfinite(px).all(-1))
        raise ConfigError(f"controller {ctrl.name} gave non-finite actions at step {t} in rows {rows[:8].tolist()}")
    return np.clip(px, 0.0, 512.0).astype(np.float32), carry


def _encode(images: np.ndarray, sample: bool):
    """PNG files of a step's images (one a live row), and each image's histogram if the step is in the stats'
    sample (counted per image: an episode left out of the dataset leaves its frames out of the statistics)."""
    from mjx_pusht.io.lerobot_dataset import histogram, png

    return [png(img) for img in images], [histogram(img) for img in images] if sample else None


def rollout_batch(env, ctrl, seeds: np.ndarray, max_steps: int, encoder, writer: LeRobotDatasetWriter,
                  keep: int, successful_only: bool = False) -> list[dict]:
    """One batch of episodes (one per seed) on the drop-in's vector env; the first `keep` episodes' frames up to
    their ends (the rest pad the batch to its compiled shape), only those that succeeded with `successful_only`.
    Each step's images of the live rows are PNG-encoded on `encoder`'s threads while the batch steps on; every
    SAMPLE-th frame of a kept episode counts into the writer's image statistics."""
    from mjx_pusht.task.controllers import seed_key

    n = env.num_envs
    key = seed_key(seeds)
    carry = ctrl.init(key)
    obs, info = env.reset(seed=[int(s) for s in seeds])
    frames = {k: [] for k in ("state", "action", "reward", "done", "success")}
    encoded = []  # (live rows, future of their PNGs)
    live = np.ones(n, bool)
    ends = np.full(n, max_steps)
    for t in range(max_steps):
        action, carry = targets_px(ctrl, carry, obs, info, t, key)
        rows = np.flatnonzero(live[:keep])
        encoded.append((rows, encoder.submit(_encode, np.asarray(obs["pixels"])[rows], t % SAMPLE == 0)))
        frames["state"].append(np.asarray(obs["agent_pos"], np.float32))
        frames["action"].append(action)
        obs, reward, terminated, truncated, info = env.step(action)
        done = np.asarray(terminated) | np.asarray(truncated)
        frames["reward"].append(np.asarray(reward, np.float32))
        frames["done"].append(done)
        frames["success"].append(np.asarray(terminated, bool))
        ends[live & done] = t + 1
        live &= ~done
        if not live.any():
            break
    stacked = {k: np.stack(v, axis=1) for k, v in frames.items()}  # (n, T, ...)
    kept = [i for i in range(keep) if not successful_only or stacked["success"][i, ends[i] - 1]]
    pngs: list[list[bytes]] = [[] for _ in range(keep)]
    for rows, future in encoded:
        files, hists = future.result()
        for j, (i, f) in enumerate(zip(rows, files, strict=True)):
            pngs[i].append(f)
            if hists is not None and i in kept:
                writer.image_histogram += hists[j]
                writer.image_frames += 1
    episodes = [{"png": pngs[i], **{k: v[i, : ends[i]] for k, v in stacked.items()}} for i in range(keep)]
    return episodes, kept


def write_demos(controller: str, seeds: np.ndarray, out: Path, *, backend: str = "auto", batch: int | None = None,
                max_steps: int = 300, action: str | None = None, replace: bool = False, progress: bool = True,
                successful_only: bool = False, share: bool = False, success_threshold: float | None = None,
                task: str = "gym-pusht") -> dict:
    """Roll out `controller` (`expert`: gym-pusht's task's expert) from each seed's gym-pusht start on the drop-in
    and write the episodes (with `successful_only`, those that succeeded) to `out` as a LeRobot dataset. An
    existing dataset in `out` is replaced only with `replace`, and only once the new one is complete. Returns a
    summary (episodes run and written, frames, success rate, the failed seeds, seconds). `success_threshold`: the
    coverage an episode succeeds and ends at (None: the task's, 0.95). `task`: gym-pusht's, or a task on its scene
    (`gym-pusht-easy`: its easy starts)."""
    import gymnasium as gym

    from mjx_pusht.backends.base import resolve
    from mjx_pusht.io.outputs import OutputError, claim_out_dir, remove_own
    from mjx_pusht.task.controllers import ControllerError, describe
    from mjx_pusht.task.tasks import get as get_task

    task = get_task(task)
    if task.variant != "gym-pusht":
        raise ConfigError(f"the demos run on the gym-pusht drop-in: the {task.name} task is on the {task.variant} scene")
    task.episode(success_threshold=success_threshold)  # a threshold outside (0, 1]: one line, before anything is written
    ctrl = task.controller(controller, action=action)
    if ctrl.pixels:
        raise ControllerError(f"controller {controller!r} acts on images; the demos hand their controller the "
                              "state (the images are rendered for the dataset): give a controller that reads the state")
    name, _ = resolve(backend)
    def refuse_a_dataset(path: Path, same: bool) -> None:
        # the same command, seeds and settings rerun into their own folder (reliability.md): the dataset is written
        # again and replaces the old one whole once complete; a dataset this command did not write is a user's
        if (path / "meta" / "info.json").exists() and not (replace or same):
            raise OutputError(f"--out {path} holds a LeRobot dataset; pass --replace to overwrite it, or choose "
                              "another --out")

    out = claim_out_dir(out, "demos", {"controller": controller, "seeds": seeds.tolist(), "backend": name,
                                       "max_steps": max_steps, "action": action,
                                       **({"successful_only": True} if successful_only else {}),
                                       **({"task": task.name} if task.name != "gym-pusht" else {}),
                                       **({"success_threshold": success_threshold} if success_threshold is not None else {})},
                         replace=replace, share=share, check=refuse_a_dataset)
    batch = min(len(seeds), batch or (64 if name == "cpu" else 1024))
    env = gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=batch, vectorization_mode="vector_entry_point",
                       backend=name, obs_type="pixels_agent_pos", observation_width=IMAGE_SIZE,
                       observation_height=IMAGE_SIZE, render_mode=None, max_episode_steps=max_steps,
                       autoreset_mode="disabled", array_type="numpy", success_threshold=success_threshold,
                       reset_kind=task.reset)
    partial = out / ".demos-partial"
    remove_own(partial)
    t0 = time.perf_counter()
    failed: list[int] = []
    writer = LeRobotDatasetWriter(partial, FPS, TASK, IMAGE_SIZE)
    with ThreadPoolExecutor() as encoder:
        for lo in range(0, len(seeds), batch):
            rows = seeds[lo : lo + batch]
            # the last batch is padded with the seeds after it: one batch shape, one compiled program
            pad = np.arange(rows[-1] + 1, rows[-1] + 1 + batch - len(rows), dtype=np.int64)
            episodes, kept = rollout_batch(env, ctrl, np.concatenate([rows, pad]), max_steps, encoder, writer,
                                           len(rows), successful_only)
            failed += [int(s) for s, ep in zip(rows, episodes) if not ep["success"][-1]]
            writer.add([episodes[i] for i in kept])
            if progress:
                print(f"demos: {lo + len(rows)}/{len(seeds)} episodes, {len(writer.episodes)} written, "
                      f"{writer.frames} frames, {time.perf_counter() - t0:.1f} s", flush=True)
        if not writer.episodes:  # a dataset of no episode is no dataset: the partial one goes, the old one stays
            remove_own(partial)
            raise ConfigError(f"none of the {len(seeds)} episodes succeeded, so none was kept (successful_only): "
                              f"nothing written to {out}")
        writer.finish()
    env.close()
    for part in ("data", "meta"):  # the new dataset replaces the old one whole, only now that it is complete
        remove_own(out / part)
        (partial / part).rename(out / part)
    partial.rmdir()
    seconds = time.perf_counter() - t0
    return {"episodes": len(seeds), "written": len(writer.episodes), "frames": writer.frames,
            "success_rate": 1 - len(failed) / len(seeds), "failed_seeds": failed, "controller": describe(ctrl),
            "backend": name, "batch": batch, "seconds": round(seconds, 2), "root": str(out)}
