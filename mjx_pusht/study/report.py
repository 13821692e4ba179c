"""The comparison reports as Markdown (open loop and closed loop), and the open loop report's plots."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_pusht.backends.results import Rollouts
from mjx_pusht.study.outcomes import DIVERGED_M
from mjx_pusht.study.stats import steps_text


def plots(out: Path, mjx_r: Rollouts, cpu_r: Rollouts, div: np.ndarray, impl: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    ax[0].scatter(cpu_r.final[:, 0], cpu_r.final[:, 2], s=4, alpha=0.5, label="cpu")
    ax[0].scatter(mjx_r.final[:, 0], mjx_r.final[:, 2], s=4, alpha=0.5, label=f"mjx-{impl}")
    ax[0].set(xlabel="final x (m)", ylabel="final yaw (rad)", title="final poses")
    ax[0].legend()
    bins = np.linspace(-np.pi, np.pi, 73)
    ax[1].hist(cpu_r.final[:, 2], bins=bins, alpha=0.6, label="cpu")
    ax[1].hist(mjx_r.final[:, 2], bins=bins, alpha=0.6, label=f"mjx-{impl}")
    ax[1].set(xlabel="final yaw (rad)", ylabel="seeds", title="outcome modes", yscale="log")
    ax[1].legend()
    frames = mjx_r.trace.qpos.shape[1]  # a seed that never parts reads `frames`, drawn in the last bin
    ax[2].hist(np.minimum(div, frames), bins=np.arange(0, frames + 4, 4))
    ax[2].set(xlabel=f"first step with tee position error > {DIVERGED_M} m", ylabel="seeds",
              title="time to divergence (last bin: never)")
    fig.tight_layout()
    fig.savefig(out / "compare.png", dpi=110)
    plt.close(fig)


def render_markdown(r: dict) -> str:
    """The report for people: what agrees exactly, when paths part, and whether outcomes match."""
    w, s, o = r["none"], r["split-tee"], r["outcomes"]
    lines = [
        f"# CPU vs {r['impl']}: fidelity report ({r['n_seeds']} seeds)",
        "",
        f"Device: {w['structure']['device']}; pusher simulated: {w['structure']['pusher_shape']}; "
        f"tree: {w['structure']['tree']['n_bodies']} bodies, nq={w['structure']['nq']} nv={w['structure']['nv']}. "
        f"The CPU reference runs the same pusher shape. Versions: {r['versions']}.",
        *(["", f"MJX options changed from the scene's: {r['mjx_options']} (the CPU reference keeps the scene's)."]
          if r.get("mjx_options") else []),
        "",
        "## Must agree",
        "| check | welded | split-tee |",
        "| --- | --- | --- |",
        f"| settle_max_abs_err (tee pose, contact-free) | {w['settle_max_abs_err']:.2e} | {s['settle_max_abs_err']:.2e} |",
        f"| verdict_agreement | {w['verdict_agreement']:.4f} | {s['verdict_agreement']:.4f} |",
        f"| settled gap max diff (m) | {w['settled_gap_max_abs_diff']:.2e} | {s['settled_gap_max_abs_diff']:.2e} |",
        f"| non-finite seeds cpu / mjx | {w['non_finite']['cpu']} / {w['non_finite']['mjx']} | "
        f"{s['non_finite']['cpu']} / {s['non_finite']['mjx']} |",
        "",
        f"Up to first contact (median step {w['first_contact_step'].get('median', float('nan')):.0f}) the tee pose "
        f"differs by at most {w['pre_contact_max_abs_err']:.2e} and the pusher by {w['pre_contact_pusher_max_abs_err']:.2e}.",
        "",
        "## When the paths part",
        f"First step with tee position error > {r['divergence']['threshold_m']} m: {_fmt(r['divergence']['step'])}; "
        f"never within the run: {r['divergence']['never_fraction']:.1%}. Steps after first contact: "
        f"{_fmt(r['divergence']['steps_after_first_contact'])}.",
        "",
        "## Outcomes as distributions",
        "Energy distance of final poses (x, y, 0.06 m x yaw) against the CPU reference:",
        "",
        "| run | energy distance (m) | median final diff (m) | seeds > 1 mm |",
        "| --- | --- | --- | --- |",
    ]
    for key, e in o["energy_distance_m"].items():
        fd = o["final_pose_diff"][key]
        lines.append(f"| {key} | {e:.2e} | {fd['median_m']:.2e} | {fd['frac_over_1mm']:.1%} |")
    lines += [
        "",
        f"**outcome_within_cpu_baseline: {o['outcome_within_cpu_baseline']}** (MJX's energy distance against the "
        "largest CPU-vs-CPU baseline).",
        "",
        "## Outcome modes",
        "| run | straight | spun ccw | spun cw |",
        "| --- | --- | --- | --- |",
    ]
    for key, m in r["modes"].items():
        if key != "definition":
            lines.append(f"| {key} | {m['straight']:.1%} | {m['spun_ccw']:.1%} | {m['spun_cw']:.1%} |")
    u = r["unexplained"]
    lines += ["", f"Seeds where MJX ends > 1 mm from CPU though the CPU is stable under float32 start jitter: "
              f"{u['fraction']:.1%} (e.g. {u['seeds'][:8]})."]
    if "root_cause" in r:
        lines += ["", "## Root cause: one change at a time", "| run | median final diff (m) | seeds > 1 mm | energy distance (m) |",
                  "| --- | --- | --- | --- |"]
        for key, v in r["root_cause"].items():
            if key == "contacts_on_cpu_states":
                continue
            if isinstance(v, str):  # a run this backend cannot make (float64 on MuJoCo Warp), and why
                lines.append(f"| {key} | {v} | | |")
                continue
            lines.append(f"| {key} | {v['final_pose_diff']['median_m']:.2e} | {v['final_pose_diff']['frac_over_1mm']:.1%} "
                         f"| {v['energy_distance_m']:.2e} |")
        c = r["root_cause"]["contacts_on_cpu_states"]
        if "mjx_active_contacts" in c:
            lines += ["", f"Contacts on the CPU's own states ({c['states']} states): CPU finds {_fmt(c['cpu_active_contacts'])} "
                      f"active contacts, MJX {_fmt(c['mjx_active_contacts'])}; the counts differ on "
                      f"{c['states_with_different_count']:.1%} of states."]
    if "warp_parts" in r:
        wp_ = r["warp_parts"]
        lines += ["", "## MJX-Warp: the collider, float32, and run-to-run reordering",
                  f"This report's MJX-Warp collides box with box through: {wp_['this_report_box_box']}.", "",
                  "| run | median final diff (m) | seeds > 1 mm | max (m) |", "| --- | --- | --- | --- |"]
        for key in [k for k in wp_ if (k.endswith("_vs_cpu") or k == "rerun_vs_first_run") and k != "energy_distance_m"]:
            v = wp_[key]
            lines.append(f"| {key} | {v['median_m']:.2e} | {v['frac_over_1mm']:.1%} | {v['max_m']:.2e} |")
        lines += ["", "`rerun_vs_first_run` is MJX-Warp against itself on the same seeds: MuJoCo Warp hands out contact "
                  "slots with atomics, so a rerun sums the constraint forces in another order. The CPU row "
                  "`cpu_start_jitter_f32` above is the float32 part."]
        f = wp_.get("first_touch_pusher_tee")
        if f:
            lines += ["", f"At each seed's first pusher-tee contact (a CPU state, {f['found_by_both']} of {f['seeds_touched']} "
                      f"seeds found by both), MuJoCo C's and MJX-Warp's GJK/EPA put the deepest contact "
                      f"{_fmt(f['contact_point_diff_m'])} m apart, depths {_fmt(f['depth_diff_m'])} m apart; "
                      f"{f['first_touch_point_over_0.1mm_apart']:.1%} of first touches are more than 0.1 mm apart. "
                      f"Of the {f['parted_seeds']} seeds that end > 1 mm apart, {f['parted_seeds_whose_first_touch_is_over_0.1mm_apart']} "
                      f"had first touches > 0.1 mm apart (parting rate {f['parted_fraction_given_first_touch_over_0.1mm']} given "
                      f"such a first touch, {f['parted_fraction_given_first_touch_within_0.1mm']} otherwise)."]
    lines += ["", "![final poses, modes, divergence](compare.png)", ""]
    return "\n".join(lines)


def _fmt(d: dict) -> str:
    if not d.get("n"):
        return "none"
    return f"median {d['median']:.3g} (p05 {d['p05']:.3g}, p95 {d['p95']:.3g}, n={d['n']})"


# --- closed loop: is a success rate measured on MJX the one MuJoCo gives? -----------------------


def render_episodes_markdown(r: dict) -> str:
    def rate(s):
        lo, hi = s["success_rate_ci95"]
        return f"{s['success_rate']:.2%} ({lo:.2%}-{hi:.2%})"

    d, dj = r["success_difference_mjx_minus_cpu"], r["success_difference_cpu_f32_minus_cpu"]
    fd = r["final_pose_diff"]
    st = r["steps_to_success_abs_diff_where_both_succeed"]
    ag = r["per_seed_success_agreement"]
    f32 = r["cpu_f32_starts"] is not None  # absent from a report paired from two evals (compare --evals)
    where = (f"Device: {r['device']}" if "cpu_device" not in r else
             f"Paired from two evals: {r['impl']} on {r['device']} ({r['evals']['mjx']}), MuJoCo C on "
             f"{r['cpu_device']} ({r['evals']['cpu']})")
    lines = [
        f"# Closed loop, CPU vs {r['impl']}: {r['controller']} on {r['n_seeds']} {r['reset']} starts",
        "",
        f"{where}; pusher: {r['pusher_shape']}; {r['episode']['max_steps']} control steps x "
        f"{r['episode']['frame_skip']} physics steps; success at coverage >= {r['episode']['success']}. "
        f"Versions: {r['versions']}.",
        "",
        "| run | success rate (95% interval) | median steps to success |",
        "| --- | --- | --- |",
        f"| CPU (MuJoCo C, float64) | {rate(r['cpu'])} | {steps_text(r['cpu']['median_steps_to_success'])} |",
        f"| {r['impl']} | {rate(r['mjx'])} | {steps_text(r['mjx']['median_steps_to_success'])} |",
    ]
    if f32:
        lines.append(f"| CPU from float32-rounded starts | {rate(r['cpu_f32_starts'])} | "
                     f"{steps_text(r['cpu_f32_starts']['median_steps_to_success'])} |")
    lines += [
        "",
        f"Success rate difference {r['impl']} - CPU: {d['difference']:+.2%} (paired 95% interval "
        f"{d['ci95'][0]:+.2%} to {d['ci95'][1]:+.2%}; {d['only_mjx']} seeds succeed only on MJX, {d['only_cpu']} only on "
        f"the CPU)." + (f" The CPU against itself from float32-rounded starts: {dj['difference']:+.2%} "
                        f"({dj['only_mjx']} / {dj['only_cpu']})." if f32 else
                        " (No CPU run from float32-rounded starts: the chaos yardstick is not in this report.)"),
        "",
    ]
    cols = [("MJX vs CPU", "mjx_vs_cpu")] + ([("CPU f32 starts vs CPU", "cpu_f32_vs_cpu")] if f32 else [])
    lines += ["| per seed | " + " | ".join(n for n, _ in cols) + " |", "| --- |" + " --- |" * len(cols),
              "| same success verdict | " + " | ".join(f"{ag[k]:.2%}" for _, k in cols) + " |",
              "| steps to success, abs diff (both succeed) | " + " | ".join(_fmt(st[k]) for _, k in cols) + " |",
              "| final position diff, median | " + " | ".join(f"{fd[k]['median_m']:.2e} m" for _, k in cols) + " |",
              "| final position diff > 1 mm | " + " | ".join(f"{fd[k]['frac_over_1mm']:.2%}" for _, k in cols) + " |",
              ""]
    return "\n".join(lines)
