"""Contacts compared across backends: the first touch, and the active contacts MuJoCo and MJX find on the same states."""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_pusht.backends.results import Rollouts
from mjx_pusht.model.scene import SceneSpec, build_model
from mjx_pusht.study.stats import distribution


def first_contact_steps(model: mujoco.MjModel, qpos_trace: np.ndarray) -> np.ndarray:
    """Per seed, the first frame whose state has the pusher touching the tee (MuJoCo's own collision)."""
    data = mujoco.MjData(model)
    pusher = model.geom("pusher_tip").id
    tee = {model.geom("tee_bar").id, model.geom("tee_stem").id}
    out = np.full(len(qpos_trace), qpos_trace.shape[1], dtype=np.int64)
    for s, traj in enumerate(qpos_trace):
        for k in range(traj.shape[0]):
            data.qpos[:] = traj[k]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_collision(model, data)
            c = data.contact
            if any(
                {int(c.geom1[i]), int(c.geom2[i])} & tee and pusher in (int(c.geom1[i]), int(c.geom2[i]))
                for i in range(data.ncon)
            ):
                out[s] = k
                break
    return out


def first_touch_contacts(backend, cpu_r: Rollouts, mjx_r: Rollouts) -> dict:
    """At each seed's first pusher-tee contact (a CPU state), the contact MuJoCo C finds and the one
    MJX-Warp finds for the very same state: how far apart the two GJK/EPA implementations put it, and
    whether the seeds that end > 1 mm apart are the ones whose first contacts already differ."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    model = build_model(backend.simulated_scene)
    first = first_contact_steps(model, cpu_r.trace.qpos)
    touched = np.flatnonzero(first < cpu_r.trace.qpos.shape[1])
    states = cpu_r.trace.qpos[touched, first[touched]]
    pusher = model.geom("pusher_tip").id
    tee = {model.geom("tee_bar").id, model.geom("tee_stem").id}

    def pick(geom, pos, dist):
        """The deepest pusher-tee contact: (x, y, depth)."""
        best = None
        for g, p, d in zip(geom, pos, dist):
            if pusher in (int(g[0]), int(g[1])) and {int(g[0]), int(g[1])} & tee and (best is None or d < best[2]):
                best = (float(p[0]), float(p[1]), float(d))
        return best

    data = mujoco.MjData(model)
    c_side = []
    for q in states:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        c = data.contact[: data.ncon]
        c_side.append(pick(c.geom, c.pos, c.dist))
    mw, mx = backend.runner.model, backend.runner.models.first()
    per = 16
    d0 = mjx.make_data(mw, impl="warp", naconmax=len(states) * per, njmax=backend.runner.buffers.rows)
    fwd = jax.jit(jax.vmap(lambda q: mjx.forward(mx, d0.replace(qpos=q))))
    d = fwd(jnp.asarray(states, jnp.float32))
    n = int(np.asarray(d._impl.nacon).reshape(-1)[0])
    geom, pos, dist = (np.asarray(x)[:n] for x in (d._impl.contact__geom, d._impl.contact__pos, d._impl.contact__dist))
    world = np.asarray(d._impl.contact__worldid)[:n]
    w_side = [pick(geom[world == i], pos[world == i], dist[world == i]) for i in range(len(states))]
    both = [i for i in range(len(states)) if c_side[i] and w_side[i]]
    dpos = np.array([np.hypot(c_side[i][0] - w_side[i][0], c_side[i][1] - w_side[i][1]) for i in both])
    ddepth = np.array([abs(c_side[i][2] - w_side[i][2]) for i in both])
    seeds_both = touched[both]
    parted = np.linalg.norm(mjx_r.final[:, :2] - cpu_r.final[:, :2], axis=1) > 1e-3
    big = dpos > 1e-4
    return {
        "seeds_touched": int(len(touched)),
        "found_by_both": int(len(both)),
        "found_by_one_only": int(sum(bool(c_side[i]) != bool(w_side[i]) for i in range(len(states)))),
        "contact_point_diff_m": distribution(dpos),
        "depth_diff_m": distribution(ddepth),
        "first_touch_point_over_0.1mm_apart": float(big.mean()) if len(big) else 0.0,
        "parted_seeds": int(parted[seeds_both].sum()),
        "parted_seeds_whose_first_touch_is_over_0.1mm_apart": int((parted[seeds_both] & big).sum()),
        "parted_fraction_given_first_touch_over_0.1mm": float(parted[seeds_both][big].mean()) if big.any() else None,
        "parted_fraction_given_first_touch_within_0.1mm": float(parted[seeds_both][~big].mean()) if (~big).any() else None,
    }


def contact_census(scene: SceneSpec, impl: str, cpu_r: Rollouts, seeds, max_seeds: int = 64) -> dict:
    """Feed the CPU's own states to MJX's collision: do both find the same contacts on the same state?"""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    model = build_model(scene)
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    k = min(max_seeds, len(seeds))
    states = cpu_r.trace.qpos[:k].reshape(-1, model.nq)
    data = mujoco.MjData(model)
    cpu_n = np.zeros(len(states), int)
    for i, q in enumerate(states):
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        cpu_n[i] = int((data.contact.dist[: data.ncon] < 0).sum()) if data.ncon else 0
    if impl != "jax":
        return {"cpu_active_contacts": distribution(cpu_n), "note": "MJX-Warp contact census not implemented"}
    mx = mjx.put_model(model, impl="jax")
    d0 = mjx.make_data(model, impl="jax")

    @jax.jit
    @jax.vmap
    def active(q):
        d = mjx.forward(mx, d0.replace(qpos=q))
        return jnp.sum(d._impl.contact.dist < 0) if hasattr(d, "_impl") and hasattr(d._impl, "contact") else jnp.sum(d.contact.dist < 0)

    mjx_n = np.asarray(active(jnp.asarray(states, jnp.float32)))
    differ = cpu_n != mjx_n
    return {
        "states": int(len(states)),
        "cpu_active_contacts": distribution(cpu_n),
        "mjx_active_contacts": distribution(mjx_n),
        "states_with_different_count": float(differ.mean()),
        "cpu_minus_mjx_when_different": distribution((cpu_n - mjx_n)[differ]),
    }
