"""False colour of lux (core.falsecolour) and its legend (core.legend).

Oracles, none taken from the code under test: published viridis entries (matplotlib's table, not
the 17 samples the ramp keeps); the sRGB relative luminance of the ramp, which must rise; round
numbers found by brute force over m x 10^k; the log scale's decade law (10 x the lux is one
decade up the ramp); the linear law t = E / top; clipping outside the scale.
"""

import math

import numpy as np
import pytest

from core.errors import SettingsError
from core.falsecolour import LOG_DECADES, RAMP, Scale, label, make_scale, percentile, ramp
from core.legend import GLYPH_H, compose, text_mask

#: Entries of matplotlib's 256-entry viridis table (index: sRGB), none a sample of RAMP.
VIRIDIS = {40: (0.270595, 0.214069, 0.507052), 100: (0.166617, 0.463708, 0.558119),
           150: (0.137339, 0.662252, 0.515571), 200: (0.440137, 0.811138, 0.340967),
           250: (0.945636, 0.899815, 0.112838)}


def _luminance(srgb):
    """Relative luminance of sRGB colours (IEC 61966-2-1 decoding, Rec. 709 weights)."""
    c = np.asarray(srgb, dtype=np.float64)
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return lin @ np.array([0.2126, 0.7152, 0.0722])


def _round_numbers(mantissas):
    return sorted(m * 10.0 ** k for k in range(-3, 8) for m in mantissas)


def _is_round_step(step):
    k = math.floor(math.log10(step))
    return any(math.isclose(step, m * 10.0 ** k, rel_tol=1e-12) for m in (1, 2, 2.5, 5))


def test_ramp_matches_published_viridis_between_its_samples():
    for index, colour in VIRIDIS.items():
        got = ramp([index / 255.0])[0]
        np.testing.assert_allclose(got, colour, atol=6 / 255)   # 17 samples, linear between


def test_ramp_lightness_rises_monotonically():
    t = np.linspace(0.0, 1.0, 2001)
    lum = _luminance(ramp(t))
    assert np.all(np.diff(lum) > 0)
    assert lum[0] < 0.05 and lum[-1] > 0.7          # dark blue to bright yellow


def test_ramp_clips_and_refuses_nan():
    np.testing.assert_array_equal(ramp([-3.0, 7.0]), ramp([0.0, 1.0]))
    with pytest.raises(ValueError, match="t must be finite"):
        ramp([0.5, np.nan])


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int64])
def test_linear_scale_is_lux_over_top_and_clips_above(dtype):
    rng = np.random.default_rng(7)
    lux = (rng.uniform(0, 1200, 500)).astype(dtype)
    scale = make_scale(lux, "linear", top=1000.0)
    t = scale.position(lux)
    np.testing.assert_allclose(t, np.minimum(lux.astype(np.float64) / 1000.0, 1.0), rtol=1e-12)
    over = lux.astype(np.float64) >= 1000.0
    assert over.any()
    np.testing.assert_array_equal(scale.colours(lux)[over], np.tile(ramp([1.0]), (over.sum(), 1)))
    np.testing.assert_array_equal(scale.colours([-5.0, 0.0])[0], scale.colours([0.0])[0])


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("weighted", [False, True])
def test_auto_top_is_the_smallest_round_number_above_the_percentile(seed, weighted):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 3000))
    lux = rng.lognormal(mean=rng.uniform(-2, 9), sigma=0.8, size=n)
    weights = rng.integers(1, 6, n) if weighted else np.ones(n, dtype=np.int64)
    # Oracle: numpy's inverted-CDF percentile of the values repeated by their (integer) weight.
    p95 = np.percentile(np.repeat(lux, weights), 95, method="inverted_cdf")
    assert percentile(lux, 95, weights if weighted else None) == p95
    for mode, mantissas in (("linear", (1, 1.5, 2, 2.5, 3, 4, 5, 6, 8)), ("log", (1, 2, 5))):
        scale = make_scale(lux, mode, weights=weights * 0.25 if weighted else None)
        want = min(v for v in _round_numbers(mantissas) if v >= p95 * (1 - 1e-12))
        assert scale.top == pytest.approx(want, rel=1e-12)
        assert scale.ticks[-1] == pytest.approx(scale.top, rel=1e-12)


def test_a_small_hot_area_does_not_set_the_top():
    # 4 % of the area at 20000 lx (beside a luminaire), the rest between 100 and 900 lx.
    lux = np.concatenate([np.linspace(100, 900, 96), np.full(400, 20000.0)])
    area = np.concatenate([np.full(96, 1.0), np.full(400, 0.01)])
    assert make_scale(lux, weights=area).top == 1000.0
    assert make_scale(lux).top == 20000.0                   # by count they are the majority


@pytest.mark.parametrize("top", [1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 0.03, 150.0,
                                 2500.0, 40000.0])
def test_linear_ticks_are_round_and_cover_the_range(top):
    ticks = np.array(make_scale([], "linear", top=top).ticks)
    assert ticks[0] == 0.0 and ticks[-1] == pytest.approx(top, rel=1e-12)
    steps = np.diff(ticks)
    assert np.allclose(steps, steps[0], rtol=1e-9)            # equal steps
    assert _is_round_step(steps[0]) and 4 <= steps.size <= 8
    for v in ticks:
        assert label(v) == f"{v:.10f}".rstrip("0").rstrip(".")   # short plain decimals


@pytest.mark.parametrize("top", [750.0, 1234.0, 0.7, 333.0])
def test_a_users_top_ends_the_ticks_after_round_steps(top):
    ticks = np.array(make_scale([], "linear", top=top).ticks)
    assert ticks[0] == 0.0 and ticks[-1] == top and np.all(np.diff(ticks) > 0)
    inner = ticks[:-1]
    step = inner[1] - inner[0]
    assert _is_round_step(step)
    assert np.allclose(inner / step, np.round(inner / step))
    assert top - inner[-1] >= 0.5 * step - 1e-9                # no crowded last label


def test_log_scale_one_decade_per_factor_ten():
    rng = np.random.default_rng(3)
    lux = rng.uniform(2.0, 90.0, 300)
    scale = make_scale(lux, "log", top=1000.0)
    assert scale.bottom == 1.0 and scale.ticks == (1.0, 10.0, 100.0, 1000.0)
    np.testing.assert_allclose(scale.position(10 * lux), scale.position(lux) + 1 / LOG_DECADES,
                               atol=1e-12)
    np.testing.assert_allclose(scale.position(lux), np.log10(lux) / LOG_DECADES, atol=1e-12)
    # Clipped at both ends.
    np.testing.assert_array_equal(scale.position([0.0, -1.0, 0.5, 1e6]), [0, 0, 0, 1])


@pytest.mark.parametrize("mode", ["linear", "log"])
def test_auto_scale_is_invariant_to_a_factor_ten(mode):
    rng = np.random.default_rng(11)
    lux = rng.gamma(2.0, 150.0, 800)
    a, b = make_scale(lux, mode), make_scale(10 * lux, mode)
    assert b.top == pytest.approx(10 * a.top, rel=1e-12)
    np.testing.assert_allclose(np.array(b.ticks), 10 * np.array(a.ticks), rtol=1e-12)
    np.testing.assert_allclose(b.colours(10 * lux), a.colours(lux), atol=1e-12)


def test_log_ticks_are_decades_of_a_round_top():
    scale = make_scale(np.full(10, 3.3e4), "log")
    assert scale.top == 5e4
    ratios = np.array(scale.ticks[1:]) / np.array(scale.ticks[:-1])
    np.testing.assert_allclose(ratios, 10.0)
    assert len(scale.ticks) == LOG_DECADES + 1
    assert scale.labels() == ("50", "500", "5000", "50000")


def test_unlit_and_empty_values_get_a_one_lux_scale():
    for lux in ([], np.zeros(5)):
        scale = make_scale(lux)
        assert scale.top == 1.0 and scale.ticks[0] == 0.0
    np.testing.assert_array_equal(make_scale(np.zeros(3)).colours(np.zeros(3)),
                                  np.tile(RAMP[0], (3, 1)))


@pytest.mark.parametrize("kwargs, message", [
    (dict(lux=[1.0, np.inf]), "lux must be finite"),
    (dict(lux=[[1.0, 2.0]]), r"lux must have shape \(n,\); got \(1, 2\)"),
    (dict(lux=[1.0], mode="cubic"), "lux_scale must be one of"),
    (dict(lux=[1.0], top=0.0), "lux_max must be"),
    (dict(lux=[1.0], top=-5.0), "lux_max must be"),
    (dict(lux=[1.0], decades=0), "decades must be an integer >= 1"),
    (dict(lux=[1.0, 2.0], weights=[1.0]), r"weights must be \(n,\) >= 0"),
    (dict(lux=[1.0, 2.0], weights=[1.0, -1.0]), r"weights must be \(n,\) >= 0"),
])
def test_bad_arguments_name_themselves(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make_scale(**kwargs)


def test_settings_errors_are_settings_errors():
    with pytest.raises(SettingsError):
        make_scale([1.0], mode="LOG")


def test_inputs_are_not_mutated():
    lux = np.array([5.0, -1.0, 300.0])
    keep = lux.copy()
    make_scale(lux, "log").colours(lux)
    np.testing.assert_array_equal(lux, keep)


# ---------------------------------------------------------------------------------- legend


def test_text_mask_shape_and_bad_characters():
    assert text_mask("1000", 2).shape == (7 * 2, (6 * 4 - 1) * 2)
    assert text_mask("1", 1).sum() > 0 and not text_mask(" ", 3).any()
    with pytest.raises(ValueError, match="characters the legend font lacks"):
        text_mask("1e3")


@pytest.mark.parametrize("mode, top", [("linear", 500.0), ("log", 2000.0)])
def test_legend_bar_shows_the_ramp_at_every_tick(mode, top):
    h, w = 300, 200
    image = np.full((h, w, 3), 0.5)
    scale = make_scale([], mode, top=top)
    out, lay = compose(image, scale)
    assert out.shape[0] == h and out.shape[1] > w
    np.testing.assert_array_equal(out[:, :w], image)           # the picture is untouched
    left, right, top_row, bottom_row = lay.bar
    ticks = np.array(scale.ticks)
    # The ramp position of each tick, computed here from the scale's definition.
    t = ticks / top if mode == "linear" else np.log10(ticks / scale.bottom) / LOG_DECADES
    rows = np.rint(bottom_row - t * (bottom_row - top_row)).astype(int)
    np.testing.assert_array_equal(rows, lay.tick_rows)
    half_row = 0.5 / (bottom_row - top_row)
    for row, ti in zip(rows, t):
        got = out[row, (left + right) // 2]
        near = ramp([max(ti - half_row, 0), min(ti + half_row, 1)])
        assert np.all(got >= near.min(axis=0) - 1e-12) and np.all(got <= near.max(axis=0) + 1e-12)
        # A white tick mark right of the bar and white label pixels beside it.
        assert np.all(out[row, right] == 1.0)
        band = out[row - GLYPH_H * lay.size // 2: row + GLYPH_H * lay.size // 2 + 1,
                   right + 4 * lay.size:]
        assert (band == 1.0).all(axis=2).sum() > 5
    # Along the bar, brightness rises from bottom to top.
    lum = _luminance(out[top_row:bottom_row + 1, (left + right) // 2][::-1])
    assert np.all(np.diff(lum) >= -1e-12) and lum[-1] > lum[0]


def test_legend_labels_are_the_scale_labels():
    scale = Scale("linear", 10.0, 0.0, (0.0, 5.0, 10.0))
    out, lay = compose(np.zeros((120, 60, 3)), scale)
    size, text_x = lay.size, lay.text_x
    assert text_x > lay.bar[1]
    for row, text in zip(lay.tick_rows, scale.labels()):
        mask = text_mask(text, size)
        y = row - (GLYPH_H * size) // 2
        ink = (out[y:y + mask.shape[0], text_x:text_x + mask.shape[1]] == 1.0).all(axis=2)
        np.testing.assert_array_equal(ink, mask)


def test_compose_refuses_a_small_or_bad_image():
    scale = make_scale([], top=10.0)
    with pytest.raises(ValueError, match="at least 56 pixels high"):
        compose(np.zeros((20, 40, 3)), scale)
    with pytest.raises(ValueError, match=r"image must have shape \(H, W, 3\); got \(80, 40\)"):
        compose(np.zeros((80, 40)), scale)
