"""The audit: every MJX sweep re-runs a seeded sample of its rows on the CPU reference and says whether they agree.

The design promises that MuJoCo C vouches for the batch; the audit puts that evidence in every
MJX sweep's own outputs. A seeded random sample (default 1% of rows, at least 64, at most 16,384)
plus every flagged row (non-finite, escaped, or SPLIT in the welded scene) runs on `cpu` with the
scene MJX simulated (the capsule pusher for MJX-JAX), from the same start poses. It agrees when
- the settle phase, contact-free, matches to 1e-5 (float32 rounding, see the compare report);
- every weld verdict is the same;
- each outcome mode's share on MJX (straight, spun ccw, spun cw) lies within the 95% Wilson
  interval of the CPU's share on the same rows.
The share of rows ending > 1 mm apart is recorded beside them (chaos at the stem makes it nonzero
even for a faithful batch: the compare report measures its baseline).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mjx_pusht.backends.results import Rollouts

AUDIT_SEED = 20261123  # the sample is the same for the same sweep
SETTLE_TOL = 1e-5
MIN_ROWS, MAX_ROWS = 64, 16384


def sample_rows(n: int, fraction: float, flagged: np.ndarray) -> np.ndarray:
    """Row indices to audit: a seeded random sample of the sweep plus every flagged row, sorted."""
    k = min(n, max(MIN_ROWS, min(MAX_ROWS, int(round(fraction * n)))))
    picked = np.random.default_rng(AUDIT_SEED).choice(n, size=k, replace=False)
    return np.union1d(picked, np.flatnonzero(flagged)).astype(np.int64)


def flagged(r: Rollouts, welded: bool) -> np.ndarray:
    return ~r.finite | ~r.contained | (~r.rigid if welded else np.zeros(len(r), bool))


def _modes(r: Rollouts) -> dict[str, np.ndarray]:
    from mjx_pusht.study.outcomes import MODES, modes
    from mjx_pusht.task.rules import wrap_angle

    m = modes(wrap_angle(r.final[:, 2]))
    return {k: m == k for k in MODES}


def compare_rows(mjx: Rollouts, cpu: Rollouts) -> dict:
    """The audit block: what was compared, the measured differences, and the verdict against the thresholds."""
    from mjx_pusht.study.stats import wilson

    ok = mjx.finite & cpu.finite
    settle = float(np.abs(mjx.settled[ok] - cpu.settled[ok]).max()) if ok.any() else float("nan")
    verdicts = float((mjx.rigid == cpu.rigid).mean())
    d = np.linalg.norm(mjx.final[:, :2] - cpu.final[:, :2], axis=1)
    modes = {}
    within = True
    mm, mc = _modes(mjx), _modes(cpu)
    n = len(mjx)
    for name in mm:
        lo, hi = wilson(int(mc[name].sum()), n)
        share = float(mm[name].mean())
        modes[name] = {"mjx": share, "cpu": float(mc[name].mean()), "cpu_ci95": [lo, hi], "within": lo <= share <= hi}
        within &= modes[name]["within"]
    agrees = bool(settle <= SETTLE_TOL and verdicts == 1.0 and within)
    return {
        "n_rows": int(n),
        "thresholds": {"settle_max_abs_err": SETTLE_TOL, "verdict_agreement": 1.0,
                       "mode_shares": "MJX's share within the CPU's 95% Wilson interval, each mode"},
        "settle_max_abs_err": settle,
        "verdict_agreement": verdicts,
        "fraction_final_over_1mm": float((d > 1e-3).mean()),
        "median_final_diff_m": float(np.median(d)) if n else float("nan"),
        "modes": modes,
        "agrees": agrees,
    }


def _cpu_scenario(backend):
    from mjx_pusht.scenario import Scenario

    sc = backend.scenario
    return Scenario(backend.simulated_scene, sc.schedule, sc.params, sc.reset, sc.controller, sc.episode, sc.randomize)


class Audit:
    """The audit of one sweep, overlapped with it: `start` puts the seeded sample's CPU rows on a
    background thread as soon as the start poses exist (the device is busy with the sweep meanwhile);
    `finish` adds the flagged rows, which only the sweep's results can name, and compares."""

    def __init__(self, backend, seeds: np.ndarray, combos: np.ndarray, fraction: float):
        self.backend, self.seeds, self.combos, self.fraction = backend, np.asarray(seeds), np.asarray(combos), fraction
        self.random = sample_rows(len(seeds), fraction, np.zeros(len(seeds), bool))
        self.future = None

    def start(self, poses=None) -> None:
        """Start the sample's CPU rows (their start poses drawn here: under several processes the
        sweep's own `poses` hold only this process's block)."""
        from concurrent.futures import ThreadPoolExecutor

        from mjx_pusht.backends.cpu import run_cpu
        from mjx_pusht.task.reset import start_poses

        self.reset = self.backend.scenario.reset
        idx = self.random
        poses = start_poses(self.seeds[idx], reset=self.reset)
        pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="audit")
        self.future = pool.submit(run_cpu, _cpu_scenario(self.backend), self.seeds[idx], combos=self.combos[idx],
                                  poses=poses)
        pool.shutdown(wait=False)

    def finish(self, rows: Rollouts, *, welded: bool, out: Path | None = None) -> dict:
        from mjx_pusht.backends.cpu import run_cpu
        from mjx_pusht.task.reset import start_poses

        if self.future is None:
            self.start()
        flags = flagged(rows, welded)
        idx = sample_rows(len(rows), self.fraction, flags)  # the random sample plus every flagged row
        extra = np.setdiff1d(idx, self.random)
        parts = [(self.random, self.future.result())]
        if len(extra):
            parts.append((extra, run_cpu(_cpu_scenario(self.backend), self.seeds[extra], combos=self.combos[extra],
                                         poses=start_poses(self.seeds[extra], reset=self.reset))))
        order = np.argsort(np.concatenate([p[0] for p in parts]), kind="stable")
        cpu = Rollouts.concat([p[1] for p in parts]).take(order)
        picked = rows.take(idx)
        block = compare_rows(picked, cpu)
        block["fraction"] = self.fraction
        block["n_flagged"] = int(flags.sum())
        block["cpu_pusher_shape"] = self.backend.simulated_scene.pusher
        if out is not None:
            from mjx_pusht.io.outputs import atomic_write_table

            cols = cpu.columns()
            cols["row"] = idx
            atomic_write_table(out / "audit_cpu.parquet", cols)
            block["cpu_rows"] = "audit_cpu.parquet"
        return block


def audit(backend, rows: Rollouts, combos: np.ndarray, fraction: float, *, welded: bool,
          out: Path | None = None) -> dict:
    """Re-run the sampled rows of a finished MJX sweep on the CPU reference and compare (see the module's doc)."""
    return Audit(backend, rows.seeds, combos, fraction).finish(rows, welded=welded, out=out)


def announce(block: dict) -> None:
    """One line on stdout when the audit agrees; a loud one on stderr when it does not."""
    m = block["modes"]
    shares = ", ".join(f"{k} {v['mjx']:.1%} vs {v['cpu']:.1%}" for k, v in m.items())
    text = (f"{block['n_rows']} rows re-run on the CPU: settle error {block['settle_max_abs_err']:.1e}, verdicts agree "
            f"{block['verdict_agreement']:.1%}, modes {shares}, {block['fraction_final_over_1mm']:.1%} end > 1 mm apart")
    if block["agrees"]:
        print(f"audit: agrees with the CPU reference ({text})")
    else:
        print(f"AUDIT: THIS SWEEP DOES NOT AGREE WITH THE CPU REFERENCE ({text}); the table is written, "
              f"but do not trust it as MuJoCo's physics", file=sys.stderr)
