"""Per-seed results, the one shape every backend returns and everything downstream reads."""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.task.invariants import stayed_rigid
from mjx_pusht.task.score import task_score

# per_seed.parquet's columns, in order
COLUMNS = (
    "seed", "start_x", "start_y", "start_yaw",
    "tee_settled_x", "tee_settled_y", "tee_settled_yaw",
    "tee_final_x", "tee_final_y", "tee_final_yaw",
    "pusher_final_x", "pusher_final_y",
    "tee_gap_settled", "tee_gap_max_dev", "tee_stayed_rigid", "finite", "contained", "mujoco_warnings",
    "task_pos_err", "task_yaw_err", "task_coverage", "task_success",
)

# the eval table adds these (per episode), after the sweep's columns and any param_ columns
EPISODE_COLUMNS = ("pusher_start_x", "pusher_start_y", "success", "steps_to_success", "episode_length",
                   "final_coverage", "best_coverage", "return")


@dataclasses.dataclass
class Trace:
    """Per-step state for a few seeds: qpos at the start (frame 0) and after every physics step."""

    qpos: np.ndarray  # (N, physics_steps + 1, nq)
    dt: float
    frame_skip: int = 1  # physics steps per control step: frame k * frame_skip ends control step k


@dataclasses.dataclass
class Rollouts:
    """One row per seed, float64 on the host whatever the backend computed in."""

    seeds: np.ndarray  # (N,) int64
    start: np.ndarray  # (N, 3) tee x, y, yaw at reset
    settled: np.ndarray  # (N, 3) after the settle phase
    final: np.ndarray  # (N, 3) after the nudge
    pusher_final: np.ndarray  # (N, 2)
    gap_settled: np.ndarray  # (N,)
    gap_max_dev: np.ndarray  # (N,) peak |gap - 0.06| over every step, start included
    finite: np.ndarray  # (N,) bool: qpos and qvel stayed finite and within mjMAXVAL at every step
    contained: np.ndarray  # (N,) bool: the tee's and the pusher's centres stayed inside the walls at every step
    trace: Trace | None = None
    params: dict[str, np.ndarray] | None = None  # per row: the swept parameter values it ran with
    pusher_start: np.ndarray | None = None  # (N, 2) pusher x, y at reset
    # per row: the episode's bookkeeping (task.episode_init): done, success, steps_to_success,
    # length, return, coverage, best_coverage; final/pusher_final are the episode's end state
    episode: dict[str, np.ndarray] | None = None
    # per row: a bitmask of the MuJoCo warnings (1 << mjtWarning) its model or its steps raised; 0: none.
    # A row with one is never rigid: a singular model "stays rigid" because nothing in it moves.
    warnings: np.ndarray | None = None

    @property
    def warned(self) -> np.ndarray:
        return np.zeros(len(self.seeds), bool) if self.warnings is None else np.asarray(self.warnings) != 0

    @property
    def rigid(self) -> np.ndarray:
        return stayed_rigid(self.gap_max_dev) & self.finite & ~self.warned

    def __len__(self) -> int:
        return len(self.seeds)

    def columns(self, *, episodes: bool = False) -> dict[str, np.ndarray]:
        """The per-seed table as named columns (see COLUMNS); with `episodes`, the eval table
        (EPISODE_COLUMNS added: the pusher's start and each episode's outcome)."""
        cols = {"seed": self.seeds.astype(np.int64)}
        for name, arr in (("start", self.start), ("tee_settled", self.settled), ("tee_final", self.final)):
            for k, axis in enumerate(("x", "y", "yaw")):
                cols[f"{name}_{axis}"] = arr[:, k]
        cols["pusher_final_x"], cols["pusher_final_y"] = self.pusher_final[:, 0], self.pusher_final[:, 1]
        cols["tee_gap_settled"] = self.gap_settled
        cols["tee_gap_max_dev"] = self.gap_max_dev
        cols["tee_stayed_rigid"] = self.rigid
        cols["finite"] = self.finite.astype(bool)
        cols["contained"] = self.contained.astype(bool)
        cols["mujoco_warnings"] = (np.zeros(len(self.seeds), np.int32) if self.warnings is None
                                   else np.asarray(self.warnings, np.int32))
        for name, v in (self.params or {}).items():
            cols[f"param_{name}"] = np.asarray(v, np.float64)
        goal = (self.episode or {}).get("goal")  # random goals: each row's, scored against and written down
        score = task_score(self.final) if goal is None else task_score(self.final, goal)
        for k, v in score.items():
            cols[f"task_{k}"] = v
        for k, axis in enumerate(("x", "y", "yaw") if goal is not None else ()):
            cols[f"goal_{axis}"] = goal[:, k]
        if episodes:
            if self.episode is None or self.pusher_start is None:
                raise ConfigError("these rollouts ran no episodes")
            cols["pusher_start_x"], cols["pusher_start_y"] = self.pusher_start[:, 0], self.pusher_start[:, 1]
            ep = self.episode
            cols["success"] = np.asarray(ep["success"], bool)
            cols["steps_to_success"] = np.asarray(ep["steps_to_success"], np.int64)
            cols["episode_length"] = np.asarray(ep["length"], np.int64)
            cols["final_coverage"] = np.asarray(ep["coverage"], np.float64)
            cols["best_coverage"] = np.asarray(ep["best_coverage"], np.float64)
            cols["return"] = np.asarray(ep["return"], np.float64)
        return cols

    @classmethod
    def from_columns(cls, cols: dict[str, np.ndarray]) -> "Rollouts":
        def stack(prefix: str) -> np.ndarray:
            return np.stack([np.asarray(cols[f"{prefix}_{a}"], np.float64) for a in ("x", "y", "yaw")], axis=-1)

        return cls(
            seeds=np.asarray(cols["seed"], np.int64),
            start=stack("start"),
            settled=stack("tee_settled"),
            final=stack("tee_final"),
            pusher_final=np.stack([cols["pusher_final_x"], cols["pusher_final_y"]], -1).astype(np.float64),
            gap_settled=np.asarray(cols["tee_gap_settled"], np.float64),
            gap_max_dev=np.asarray(cols["tee_gap_max_dev"], np.float64),
            finite=np.asarray(cols["finite"], bool),
            contained=np.asarray(cols["contained"], bool),
            warnings=np.asarray(cols["mujoco_warnings"], np.int32) if "mujoco_warnings" in cols else None,
            params={k.removeprefix("param_"): np.asarray(v, np.float64) for k, v in cols.items()
                    if k.startswith("param_")} or None,
            pusher_start=(np.stack([cols["pusher_start_x"], cols["pusher_start_y"]], -1).astype(np.float64)
                          if "pusher_start_x" in cols else None),
            episode=({"success": np.asarray(cols["success"], bool), "steps_to_success": np.asarray(cols["steps_to_success"]),
                      "length": np.asarray(cols["episode_length"]), "coverage": np.asarray(cols["final_coverage"]),
                      "best_coverage": np.asarray(cols["best_coverage"]), "return": np.asarray(cols["return"]),
                      "done": np.asarray(cols["success"], bool)} | ({"goal": stack("goal")} if "goal_x" in cols else {})
                     if "success" in cols else None),
        )

    @classmethod
    def concat(cls, parts: list["Rollouts"]) -> "Rollouts":
        optional = ("trace", "params", "pusher_start", "episode", "warnings")
        fields = [f.name for f in dataclasses.fields(cls) if f.name not in optional]
        out = cls(**{f: np.concatenate([getattr(p, f) for p in parts]) for f in fields})
        if parts and any(p.warnings is not None for p in parts):
            out.warnings = np.concatenate([p.warnings if p.warnings is not None else np.zeros(len(p), np.int32)
                                           for p in parts])
        if parts and parts[0].params:
            out.params = {k: np.concatenate([p.params[k] for p in parts]) for k in parts[0].params}
        if parts and all(p.pusher_start is not None for p in parts):
            out.pusher_start = np.concatenate([p.pusher_start for p in parts])
        if parts and all(p.episode is not None for p in parts):
            out.episode = {k: np.concatenate([p.episode[k] for p in parts]) for k in parts[0].episode}
        return out

    def take(self, idx) -> "Rollouts":
        """Rows `idx`, in that order (the per-row extras too; the trace is not carried)."""
        optional = ("trace", "params", "pusher_start", "episode", "warnings")
        out = Rollouts(**{f.name: getattr(self, f.name)[idx] for f in dataclasses.fields(self) if f.name not in optional})
        out.warnings = self.warnings[idx] if self.warnings is not None else None
        out.params = {k: v[idx] for k, v in self.params.items()} if self.params else None
        out.pusher_start = self.pusher_start[idx] if self.pusher_start is not None else None
        out.episode = {k: v[idx] for k, v in self.episode.items()} if self.episode is not None else None
        return out

    @classmethod
    def empty(cls) -> "Rollouts":
        z = np.zeros((0, 3))
        b = np.zeros(0, bool)
        return cls(np.zeros(0, np.int64), z, z, z, np.zeros((0, 2)), np.zeros(0), np.zeros(0), b, b)


def from_carry(seeds, poses, pusher_start, carry) -> Rollouts:
    """A backend's final carry as per-seed rows (float64 on the host), whichever backend made it."""
    acc, ep = carry["inv"], carry["ep"]
    f64 = lambda a: np.asarray(a, np.float64)  # noqa: E731
    return Rollouts(
        seeds=seeds,
        start=f64(poses[:, :3]),
        settled=f64(acc["tee_settled"]),
        final=f64(carry["final"]),
        pusher_final=f64(carry["pusher_final"]),
        gap_settled=f64(acc["gap_settled"]),
        gap_max_dev=f64(acc["gap_max_dev"]),
        finite=np.asarray(acc["finite"], bool),
        contained=np.asarray(acc["contained"], bool),
        pusher_start=f64(pusher_start),
        # random goals (task/goals.py): each episode's goal, which its reset drew and it was scored against
        episode={k: np.asarray(v) for k, v in ep.items()} | ({"goal": f64(carry["goal"])} if "goal" in carry else {}),
    )


def round6(v) -> float:
    return round(float(v), 6)


def scene_metrics(rollouts: Rollouts, row: int, tree, break_it: str) -> dict:
    """The chapter's metrics.json for one row: exactly its keys, rounded to 6 decimals as it rounds."""
    return {
        "break_it": break_it,
        "joint_types": tree.joint_types,
        "n_bodies": tree.n_bodies,
        "n_geoms": tree.n_geoms,
        "n_joints": tree.n_joints,
        "nq": tree.nq,
        "nu": tree.nu,
        "nv": tree.nv,
        "pusher_final": [round6(v) for v in rollouts.pusher_final[row]],
        "seed": int(rollouts.seeds[row]),
        "tee_final_pose": [round6(v) for v in rollouts.final[row]],
        "tee_gap_max_dev": round6(rollouts.gap_max_dev[row]),
        "tee_gap_settled": round6(rollouts.gap_settled[row]),
        "tee_settled_pose": [round6(v) for v in rollouts.settled[row]],
        "tee_stayed_rigid": bool(rollouts.rigid[row]),
    }
