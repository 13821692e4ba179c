"""The drop-in's side-by-side picture (`python -m benchmarks.gym_pusht --picture`): each panel is the image its
row's env returns for its column's state, drawn 3x, under a label band naming the env (the rows' bands differ)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

import mjx_pusht  # noqa: F401  (registers the env ids)

pytest.importorskip("gym_pusht")  # a test extra: pip install 'mjx-pusht[test]'


def test_every_panel_is_its_envs_own_image_under_a_label(tmp_path):
    from benchmarks.gym_pusht import BAND, PICTURE_ROWS, PICTURE_STATES, SCALE, picture

    picture(str(tmp_path / "p.png"))
    img = np.asarray(Image.open(tmp_path / "p.png").convert("RGB"))
    side = 96 * SCALE
    assert img.shape == (len(PICTURE_ROWS) * (side + BAND), len(PICTURE_STATES) * side, 3)
    bands, shown = [], []
    for r, (env_id, _) in enumerate(PICTURE_ROWS):
        top = r * (side + BAND)
        bands.append(img[top:top + BAND])
        assert (bands[-1].min(-1) < 100).sum() > 200  # dark text drawn in the band
        env = gym.make(env_id, obs_type="pixels")
        for c, state in enumerate(PICTURE_STATES):
            panel = img[top + BAND:top + BAND + side, c * side:(c + 1) * side]
            own = env.reset(options={"reset_to_state": list(state)})[0]
            assert np.array_equal(panel, own.repeat(SCALE, 0).repeat(SCALE, 1))  # its env's image, 3x nearest
            shown.append(own)
        env.close()
    assert not np.array_equal(bands[0], bands[1])  # each row names its own env
    assert not all(np.array_equal(a, b) for a, b in zip(shown[:4], shown[4:]))  # two renderers: not one row twice
