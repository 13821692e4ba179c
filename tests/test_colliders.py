"""The same collision functions as MuJoCo C: the table `tree --colliders` prints, and MJX-Warp's box-box contacts."""

from __future__ import annotations

import json
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from mjx_pusht.model.colliders import contacts_c
from mjx_pusht.model.scene import SceneSpec, build_model


@pytest.mark.slow
def test_tree_colliders_lists_every_pair_the_scene_can_collide():
    r = subprocess.run([sys.executable, "-m", "mjx_pusht", "tree", "--colliders", "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    # by hand from the MJCF: 4 walls x (bar, stem, pusher) + (bar, stem) x pusher; the table, the
    # target and wall-wall pairs never collide (collision off, or both static)
    walls = [f"wall_{s}" for s in "nsew"]
    expect = {frozenset(p) for p in [(w, g) for w in walls for g in ("tee_bar", "tee_stem", "pusher_tip")]
              + [("tee_bar", "pusher_tip"), ("tee_stem", "pusher_tip")]}
    assert {frozenset(r["geoms"]) for r in rows} == expect and len(rows) == 14
    for row in rows:
        if row["types"] == ["box", "box"]:
            assert row["mujoco_c"].startswith("primitive") and row["mjx_warp"] == "primitive box_box"
            assert row["mjx_jax"].startswith("box_box")
        else:
            assert sorted(row["types"]) == ["box", "cylinder"]
            assert row["mujoco_c"].startswith("general convex") and "GJK/EPA" in row["mjx_warp"]
            assert row["mjx_jax"].startswith("capsule_convex")


def _tee_against_north_wall(model, yaw):
    """qpos with the bar's top 1 mm into the north wall (inner face at y = 0.39), at a small yaw."""
    q = model.qpos0.copy()
    reach = 0.06 * abs(np.sin(yaw)) + 0.015 * np.cos(yaw)  # the bar's highest corner above its centre
    q[0], q[1], q[2] = 0.05, 0.39 - reach + 0.001, yaw
    q[3], q[4] = 0.0, -0.3
    return q


@pytest.mark.slow
@pytest.mark.warp
def test_mjx_warp_box_box_contacts_match_mujoco_c():
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    from mjx_pusht.backends.mjx import MjxConfig, mjx_model

    model = build_model(SceneSpec())
    forward = jax.jit(mjx.forward)

    def worst(match: bool) -> float:
        """The largest contact position or depth difference from MuJoCo C over a few tee-on-wall states."""
        mw = mjx_model(SceneSpec(), MjxConfig(impl="warp", match_c_colliders=match))
        assert bool(mw.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_NATIVECCD) == match
        mx = mjx.put_model(mw, impl="warp")
        err = 0.0
        for yaw in (0.0, 0.01, 0.05, -0.1):
            q = _tee_against_north_wall(model, yaw)
            want = contacts_c(model, q)
            assert len(want) >= 2 and all(model.geom(c[0]).name == "wall_n" for c in want)
            d = mjx.make_data(mw, impl="warp", naconmax=64, njmax=96).replace(qpos=jnp.asarray(q, jnp.float32))
            d = forward(mx, d)
            n = int(d._impl.nacon[0])
            got = sorted((int(g[0]), int(g[1]), tuple(float(x) for x in p), float(s)) for g, p, s in zip(
                np.asarray(d._impl.contact__geom)[:n], np.asarray(d._impl.contact__pos)[:n],
                np.asarray(d._impl.contact__dist)[:n]))
            assert [c[:2] for c in got] == [c[:2] for c in want], (match, yaw)  # the same count and pairs
            err = max(err, np.abs(np.array([c[2] for c in got]) - np.array([c[2] for c in want])).max(),
                      np.abs(np.array([c[3] for c in got]) - np.array([c[3] for c in want])).max())
        return err

    assert not model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_NATIVECCD  # the CPU reference untouched
    # primitive box_box: MuJoCo C's contacts to float32 rounding (positions ~0.4 m, so ~3e-8)
    assert worst(True) < 3e-7
    # the test can tell: MuJoCo Warp's default GJK/EPA route puts the same contacts microns away
    assert worst(False) > 1e-6
