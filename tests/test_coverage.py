"""The fidelity report: what must agree does, the report parses, and its statistics are right."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.task.score import T_AREA, coverage, task_score, wrap_angle  # noqa: E402


def test_the_target_covers_itself_completely():
    assert coverage(np.array([[0.0, 0.0, 0.0]]))[0] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("dx", [0.002, 0.01, 0.014])
def test_coverage_of_a_shifted_tee_matches_the_analytic_overlap(dx):
    # Shifted along x by dx < 0.015: the bars overlap over (0.12 - dx) x 0.03, the stems over
    # (0.03 - dx) x 0.09, and a bar and a stem only share an edge (zero area).
    expect = ((0.12 - dx) * 0.03 + (0.03 - dx) * 0.09) / T_AREA
    assert coverage(np.array([[dx, 0.0, 0.0]]))[0] == pytest.approx(expect, rel=1e-9)


def test_coverage_of_a_tee_turned_half_round_is_the_bar_alone():
    # rotated by pi about the bar centre, only the bars coincide: 0.0036 of 0.0063 m^2
    assert coverage(np.array([[0.0, 0.0, np.pi]]))[0] == pytest.approx(0.0036 / 0.0063, rel=1e-9)


def test_coverage_is_zero_far_away_and_yaw_error_wraps():
    assert coverage(np.array([[0.3, 0.3, 0.0]]))[0] == 0.0
    assert wrap_angle(np.array([3 * np.pi / 2, -np.pi, np.pi]))[0] == pytest.approx(-np.pi / 2)
    assert list(wrap_angle(np.array([-np.pi, np.pi]))) == [np.pi, np.pi]
    s = task_score(np.array([[0.03, 0.04, 2 * np.pi + 0.1]]))
    assert s["pos_err"][0] == pytest.approx(0.05) and s["yaw_err"][0] == pytest.approx(0.1)


def _raster_coverage(pose, h=2.5e-4):
    """An independent estimate: count grid cells (cell centres) inside both Ts; error ~ perimeter * h."""
    xs = np.arange(-0.06 + h / 2, 0.06, h)
    ys = np.arange(-0.105 + h / 2, 0.015, h)
    gx, gy = np.meshgrid(xs, ys)
    inside_target = (np.abs(gy) <= 0.015) | ((np.abs(gx) <= 0.015) & (gy <= -0.015))
    px, py = gx[inside_target], gy[inside_target]  # target-T cells
    c, s = np.cos(pose[2]), np.sin(pose[2])
    lx = c * (px - pose[0]) + s * (py - pose[1])  # into the block's frame
    ly = -s * (px - pose[0]) + c * (py - pose[1])
    in_block = ((np.abs(lx) <= 0.06) & (np.abs(ly) <= 0.015)) | ((np.abs(lx) <= 0.015) & (ly <= -0.015) & (ly >= -0.105))
    return in_block.sum() / inside_target.sum()


def test_coverage_matches_an_independent_raster_on_random_poses():
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-0.08, 0.08, 40), rng.uniform(-0.08, 0.08, 40), rng.uniform(-np.pi, np.pi, 40)])
    exact = coverage(poses)
    raster = np.array([_raster_coverage(p) for p in poses])
    np.testing.assert_allclose(exact, raster, atol=0.01)
    assert (exact > 0.2).sum() > 5  # the sample does reach well-overlapping poses


def test_the_far_away_shortcut_changes_no_coverage():
    from mjx_pusht.task.rules import coverage as coverage_everywhere

    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-0.25, 0.25, 4000), rng.uniform(-0.25, 0.25, 4000), rng.uniform(-np.pi, np.pi, 4000)])
    brute = coverage_everywhere(poses)
    np.testing.assert_allclose(coverage(poses), brute, atol=1e-12)
    assert (brute > 0).sum() > 100  # the sample does reach overlapping poses


def test_coverage_is_the_same_function_under_jax():
    import jax
    import jax.numpy as jnp

    from mjx_pusht.task.rules import coverage as coverage_xp

    rng = np.random.default_rng(4)
    poses = np.column_stack([rng.uniform(-0.1, 0.1, 64), rng.uniform(-0.1, 0.1, 64), rng.uniform(-np.pi, np.pi, 64)])
    one = jax.jit(jax.vmap(coverage_xp))(jnp.asarray(poses, jnp.float32))
    np.testing.assert_allclose(np.asarray(one), coverage(poses), atol=2e-5)
