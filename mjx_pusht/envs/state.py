"""The functional env's `State`: one batch of episodes, every field an array over the batch (functional.py)."""

from __future__ import annotations

from typing import Any, NamedTuple


class State(NamedTuple):
    """One batch of episodes. `data` is the backend's physics state; the rest is arrays."""

    data: Any  # mjx.Data (batched) or the CPU's MjData copies
    carry: dict  # episode.begin's carry: invariants, episode bookkeeping, end poses
    obs: dict  # {"state": (N, 5), "keypoints": (N, 16)}
    reward: Any  # (N,) coverage after the last step (0 for an ended episode)
    terminated: Any  # (N,) bool: coverage reached the success threshold
    truncated: Any  # (N,) bool: max_steps control steps taken without success
    step: Any  # (N,) int32 control steps taken
    key: Any  # (N, 2) uint32 seed words
    dropped: Any = None  # (N,) int32 MJX-Warp overflow bits since reset (0: nothing dropped); None on cpu/mjx-jax
    info: Any = None  # wrappers' own arrays (wrappers.AutoReset: the start pool, the ended episodes' outcome)
    physics: Any = None  # (N, k) each episode's physics factors, drawn from its seed (`randomize`); None: the scene's

    @property
    def metrics(self) -> dict:
        """coverage, best_coverage, return, success, steps_to_success, and the invariants."""
        ep, inv = self.carry["ep"], self.carry["inv"]
        return {k: ep[k] for k in ("coverage", "best_coverage", "return", "success", "steps_to_success")} | {
            "gap_max_dev": inv["gap_max_dev"], "finite": inv["finite"], "contained": inv["contained"]}
