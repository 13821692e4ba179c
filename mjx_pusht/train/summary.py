"""A training run's summary.json: method, observation, env steps, wall-clock (simulation / learning), device,
versions, the kept fit's held-out success with its 95% interval, and the curve (`write_summary`, which also
writes the curve's files)."""

from __future__ import annotations

from pathlib import Path

from mjx_pusht.io.outputs import atomic_write_json
from mjx_pusht.train.curve import write_curve
from mjx_pusht.train.resume import config_dict


def write_summary(cfg, backend, out: Path, curve, rerun: bool = True, method: str = "dagger",
                  kept: dict | None = None, keep: str = "last", devices: int = 1) -> dict:
    """summary.json (and the curve's files) of a `method` run on `backend`; `kept`: the curve row of the fit
    that is the run's policy (the last row when None), chosen by the rule `keep`; `devices`: how many it trained
    on (`train --devices`). Returns the summary."""
    from mjx_pusht.backends.base import versions

    last = curve[-1] if curve else None
    final = kept or last
    summary = {
        "method": method, "obs_type": cfg.obs_type, "backend": backend, "device": _device(backend), "devices": devices,
        "versions": versions(), "config": config_dict(cfg), "iterations_run": len(curve),
        "env_steps": last["env_steps"] if last else 0,
        "wall_seconds": round(last["wall_seconds"], 3) if last else 0.0,
        "simulation_seconds": round(sum(r["sim_seconds"] for r in curve), 3),
        "learning_seconds": round(sum(r["learn_seconds"] for r in curve), 3),
        "held_out": {"seeds": f"{cfg.held_out_seeds()[0]}:{cfg.held_out_seeds()[-1] + 1}", "reset": cfg.reset,
                     "task": getattr(cfg, "task", None) or "chapter",
                     "success_coverage": cfg.episode().success, "max_steps": cfg.max_steps,
                     "goal": getattr(cfg, "goal", None) or "fixed"}
        | ({"randomize": config_dict(cfg)["randomize"]} if getattr(cfg, "randomize", None) else {}),
        # the trainer's own judgement of the kept policy (its jitted rollout, in its batch); `train` adds eval's
        # (held_out_success), the number to report: the same policy and seeds in eval's episode programs, equal on
        # the CPU and parting on a GPU only where float32 rounding turns a contact-rich episode (notebook change 24)
        "trainer_success": final["success"] if final else None,
        "trainer_success_ci95": [final["success_lo"], final["success_hi"]] if final else None,
        "kept": {"rule": keep, "iteration": final["iteration"], "validation_success": final.get("validation_success"),
                 "validation_beta": final.get("validation_beta")} if final else None,
        "policy": "policy.msgpack",  # paths in a summary are relative to its folder, never the machine's
        "curve": curve,
    }
    if method == "ppo":
        summary["wall_clock_note"] = ("simulation_seconds is the held-out judging; learning_seconds is Brax's training "
                                      "epochs, whose rollouts (simulation) and updates run in one program")
    title = {"dagger": "DAgger", "ppo": "Brax PPO"}[method]
    on = f"{devices} x {summary['device']}" if devices > 1 else summary["device"]  # a 4-GPU curve says so
    write_curve(out, curve, f"{title} from {cfg.obs_type}, {backend} on {on}", rerun)
    atomic_write_json(out / "summary.json", summary)
    return summary


def _device(backend: str) -> str:
    if backend == "cpu":
        import os

        return f"cpu ({os.cpu_count()} cores)"
    import jax

    return str(jax.devices()[0].device_kind)
