"""Domain randomisation of rendered views (sixdpose.generation.randomise): pure NumPy, no Drake."""

from __future__ import annotations

import numpy as np
import pytest

from sixdpose.generation.randomise import SceneLook, ViewLook, randomise_view, scene_look, view_look
from sixdpose.generation.sim import EMPTY_LABEL, GROUND_LABEL, GROUND_RGB, TABLE_LABEL, TABLE_RGB

H, W = 60, 80


def _view():
    """A render: table (left half, shaded 0.8), floor (top right), empty (bottom-right corner), a noise
    object (label 3, a grey ramp) and a target (label 2, a random texture)."""
    rng = np.random.default_rng(0)
    label = np.full((H, W), TABLE_LABEL, np.int32)
    label[:, 40:] = GROUND_LABEL
    label[50:, 70:] = EMPTY_LABEL
    label[10:20, 10:20] = 2
    label[30:40, 50:60] = 3
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[label == TABLE_LABEL] = np.rint(255 * 0.8 * np.array(TABLE_RGB))
    rgb[label == GROUND_LABEL] = np.rint(255 * 0.7 * np.array(GROUND_RGB))
    rgb[label == EMPTY_LABEL] = (204, 229, 255)
    rgb[label == 2] = rng.integers(0, 256, (100, 3))
    rgb[label == 3] = np.linspace(40, 200, 100)[:, None].astype(np.uint8)
    return rgb, label


NEUTRAL = ViewLook(1.0, 1.0, np.ones(3, np.float32), np.array([1.0, 0.0]), 0.0, 7)


def test_strength_zero_changes_nothing():
    """At strength 0 the looks are the defaults and the image comes back byte-identical."""
    rgb, label = _view()
    look = scene_look(700, 3, [3], 0.0)
    np.testing.assert_allclose(look.table, TABLE_RGB, atol=1e-6)
    np.testing.assert_allclose(look.ground, GROUND_RGB, atol=1e-6)
    assert not look.texture.any()
    v = view_look(700, 3, 1, 0.0)
    assert (v.gain, v.gamma, v.falloff) == (1.0, 1.0, 0.0) and np.all(v.white_balance == 1)
    np.testing.assert_array_equal(randomise_view(rgb, label, look, v), rgb)


def test_table_gets_the_new_diffuse_colour_exactly_and_targets_keep_theirs():
    """rgb * d_new / d_default: a table shaded 0.8 becomes 0.8 d_new; with a neutral view the target's
    pixels are untouched; the noise object's colour changes but keeps its light/dark ramp."""
    rgb, label = _view()
    look = SceneLook(np.array([0.2, 0.5, 0.9], np.float32), np.array([0.9, 0.1, 0.1], np.float32),
                     np.array([0.0, 1.0, 0.0], np.float32), np.zeros(3, np.float32),
                     {3: (np.array([0.1, 0.2, 0.9], np.float32), None)}, 1.0)
    out = randomise_view(rgb, label, look, NEUTRAL)
    table = out[label == TABLE_LABEL].astype(float)
    shade = rgb[label == TABLE_LABEL].astype(float) / 255 / np.array(TABLE_RGB)
    np.testing.assert_allclose(table, np.clip(255 * shade * [0.2, 0.5, 0.9], 0, 255), atol=1.01)
    np.testing.assert_allclose(out[label == GROUND_LABEL][0], np.rint(255 * 0.7 * np.array([0.9, 0.1, 0.1])), atol=1.01)
    assert tuple(out[label == EMPTY_LABEL][0]) == (0, 255, 0)
    np.testing.assert_array_equal(out[label == 2], rgb[label == 2])
    noise = out[label == 3].astype(float)
    assert np.all(noise[:, 2] >= noise[:, 0]) and np.corrcoef(noise[:, 2], rgb[label == 3][:, 0])[0, 1] > 0.99


def test_scenes_differ_views_differ_and_draws_repeat():
    """Two scenes get different table colours; the same (seed, scene) gives the same look; views of a
    scene get different exposures; the strength is bounded."""
    a, b = scene_look(700, 0, [4, 5], 1.0), scene_look(700, 1, [4, 5], 1.0)
    assert np.abs(a.table - b.table).max() > 0.05
    again = scene_look(700, 0, [4, 5], 1.0)
    np.testing.assert_array_equal(a.table, again.table)
    assert all(np.array_equal(a.noise[k][0], again.noise[k][0]) for k in (4, 5))
    gains = {view_look(700, 0, v, 1.0).gain for v in range(4)}
    assert len(gains) == 4 and all(0.6 <= g <= 1.5 for g in gains)
    rgb, label = _view()
    o1 = randomise_view(rgb, label, a, view_look(700, 0, 0, 1.0))
    np.testing.assert_array_equal(o1, randomise_view(rgb, label, again, view_look(700, 0, 0, 1.0)))
    assert not np.array_equal(o1, randomise_view(rgb, label, b, view_look(700, 1, 0, 1.0)))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        scene_look(0, 0, [], 1.5)
    with pytest.raises(ValueError, match="uint8"):
        randomise_view(rgb.astype(np.float32), label, a, NEUTRAL)


def test_config_field_bounded_and_on_in_ycbv_only():
    """randomise is a bounded config field, 0 by default and in every profile but ycbv / ycbv_ideal."""
    from sixdpose.errors import ConfigError
    from sixdpose.generation.config import PROFILES, GenerationConfig, profile

    assert GenerationConfig().randomise == 0.0
    assert {k for k, c in PROFILES.items() if c.randomise > 0} == {"ycbv", "ycbv_ideal"}
    assert profile("smoke", randomise=0.5).randomise == 0.5
    with pytest.raises(ConfigError, match="randomise"):
        profile("smoke", randomise=1.5)
