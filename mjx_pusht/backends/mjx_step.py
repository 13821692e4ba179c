"""One MJX world: the model MJX simulates (`MjxConfig`, `simulated_scene`, `mjx_model`) and its control step
(`advance`, `physics_for`: the MJX side of `task.episode.control_step`), shared by the batched rollout (mjx.py)
and the functional env.
"""

from __future__ import annotations

import dataclasses

import mujoco

from mjx_pusht.model.scene import SceneSpec, build_model
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.episode import after_physics_step

IMPLS = ("jax", "warp")
PUSHER_FOR_IMPL = {"jax": "capsule", "warp": "cylinder"}


@dataclasses.dataclass(frozen=True)
class MjxConfig:
    """How MJX runs: implementation, precision and solver settings (None: the scene's own)."""

    impl: str = "jax"
    x64: bool = False
    iterations: int | None = None
    ls_iterations: int | None = None
    tolerance: float | None = None
    # MJX-Warp buffers per world; None: start at the typical need and grow on overflow
    contacts_per_world: int | None = None
    constraints_per_world: int | None = None
    # MJX-Warp only: who captures the CUDA graph, a warp.JaxCallableGraphMode name; None: MJX's default
    graph_mode: str | None = None
    # MJX-Warp only: compile the scene's kernels on all cores up front (False: lazily, one by one)
    precompile: bool = True
    # MJX-Warp only: collide box with box through MuJoCo Warp's primitive box_box, as MuJoCo C does
    # (mjc_BoxBox), by setting mjDSBL_NATIVECCD on the model MJX receives; see colliders.py
    match_c_colliders: bool = True
    # each action checked for finiteness in the scan (actions.py); off only to time the check (benchmarks)
    check_actions: bool = True


def simulated_scene(scenario: Scenario, impl: str) -> SceneSpec:
    """The scene an impl runs: jax substitutes a capsule for the chapter's cylinder (gym-pusht's agent: a sphere)."""
    keep = scenario.scene.variant != "chapter"
    return scenario.scene if keep else dataclasses.replace(scenario.scene, pusher=PUSHER_FOR_IMPL[impl])


def mjx_model(scene: SceneSpec, cfg: MjxConfig) -> mujoco.MjModel:
    model = build_model(scene)
    # MJX never resets a diverged world (NaN simply propagates into the finite
    # flag), and MuJoCo Warp refuses the flag outright, so clear it here.
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    if cfg.impl == "warp" and cfg.match_c_colliders:
        # MuJoCo Warp sends box-box to GJK/EPA unless this bit is set; MuJoCo C always uses its
        # primitive mjc_BoxBox (its contacts are the same with the bit on or off: colliders.py)
        model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    if cfg.iterations is not None:
        model.opt.iterations = cfg.iterations
    if cfg.ls_iterations is not None:
        model.opt.ls_iterations = cfg.ls_iterations
    if cfg.tolerance is not None:
        model.opt.tolerance = cfg.tolerance
    return model


def advance(mx, d, carry, u, k, frame_skip: int, settle_step: int, layout, warp: bool, ovf, qs=None):
    """One control step of one world: `frame_skip` mjx.steps at ctrl u, each folded into the invariants.

    `ovf` accumulates MJX-Warp's overflow bits; `qs`, when given, records qpos after every
    physics step (the trace).
    """
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    def physics_step(inner, j):
        d, carry, ovf, qs = inner
        t = k * frame_skip + j
        d = mjx.step(mx, d.replace(ctrl=u))
        carry = after_physics_step(carry, t, settle_step, layout, d.qpos, d.qvel, d.sensordata, jnp)
        if warp:
            ovf = ovf | d._impl.overflow
        if qs is not None:
            # Written into the carry, not stacked as scan output: under MJX-Warp's CUDA-graph
            # capture on an H100 the stacked per-step qpos came back stale (frame 1 read as
            # qpos0) while the carried state was right.
            qs = qs.at[t].set(d.qpos)
        return (d, carry, ovf, qs), None

    if frame_skip == 1:  # the chapter's schedule acts every physics step: no inner loop
        (d, carry, ovf, qs), _ = physics_step((d, carry, ovf, qs), 0)
    else:
        (d, carry, ovf, qs), _ = jax.lax.scan(physics_step, (d, carry, ovf, qs), jnp.arange(frame_skip))
    return d, carry, ovf, qs


def physics_for(mx, frame_skip: int, settle_step: int, layout, warp: bool):
    """The MJX side of `task.episode.control_step`: `physics(sim, u, carry, k)` steps one world."""

    def physics(sim, u, carry, k):
        d, ovf, qs = sim
        d, carry, ovf, qs = advance(mx, d, carry, u, k, frame_skip, settle_step, layout, warp, ovf, qs)
        return d.qpos, carry, (d, ovf, qs)

    return physics
