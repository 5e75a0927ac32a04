"""Metrics on arrays whose answers are known by construction."""

import numpy as np
import pytest

from bench.compare import metrics


def test_face_values_mean_of_corners_any_corner_order():
    # Two faces stored out of order: face 0 uses corners 3..6, face 1 corners 0..2.
    cc = np.arange(21, dtype=float).reshape(7, 3)
    out = metrics.face_values(cc, [3, 0], [4, 3])
    np.testing.assert_allclose(out[0], cc[3:7].mean(axis=0))
    np.testing.assert_allclose(out[1], cc[0:3].mean(axis=0))


def test_relative_rms_and_p95_closed_form():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.2, 1.0, size=(1000, 1)) * np.ones((1, 3))
    rel = rng.uniform(-0.1, 0.1, size=1000)
    area = rng.uniform(0.5, 2.0, size=1000)
    test = ref * (1 + rel)[:, None]
    got = metrics.relative_errors(test, ref, area)
    w = area / area.sum()
    assert got["rms"] == pytest.approx(np.sqrt(np.sum(w * rel ** 2)), rel=1e-12)
    assert got["bias"] == pytest.approx(np.sum(w * rel), abs=1e-12)
    # p95 of |rel| under area weights: independent computation by sorting and scanning.
    order = np.argsort(np.abs(rel))
    cum = np.cumsum(w[order])
    assert got["p95"] == pytest.approx(np.abs(rel)[order][np.argmax(cum >= 0.95 - 1e-12)])


def test_uniform_scale_error_is_exact_and_mask_excludes_faces():
    ref = np.ones((4, 3))
    test = ref * np.array([1.05, 1.05, 1.05, 9.0])[:, None]
    got = metrics.relative_errors(test, ref, np.ones(4), mask=[True, True, True, False])
    assert got["rms"] == pytest.approx(0.05)
    assert got["p95"] == pytest.approx(0.05)
    assert got["faces"] == 3


def test_dark_faces_are_left_out():
    ref = np.array([[1.0] * 3, [1e-9] * 3])
    test = np.array([[1.0] * 3, [1.0] * 3])
    assert metrics.relative_errors(test, ref, [1.0, 1.0])["rms"] == 0.0


def test_luminance_weights_sum_to_one():
    assert metrics.luminance(np.ones((2, 3))) == pytest.approx([1.0, 1.0])


def test_pareto_front():
    t = np.array([1.0, 2.0, 3.0, 4.0, 2.0])
    e = np.array([0.5, 0.6, 0.1, 0.05, 0.3])
    # run 1 is beaten by run 4 (same time, lower error) and run 0 (faster, lower error).
    assert metrics.pareto_front(t, e).tolist() == [0, 4, 2, 3]


def test_time_to_reach():
    assert metrics.time_to_reach([1, 2, 3], [0.1, 0.04, 0.01], 0.05) == 2
    assert metrics.time_to_reach([1, 2], [0.1, 0.2], 0.05) == np.inf


@pytest.mark.parametrize("args, match", [
    (((np.ones((2, 2)),), [0], [2]), "corner_colours"),
    ((np.ones((3, 3)), [0], [4]), "index into"),
    ((np.ones((3, 3)), [0, 1], [3]), "equal length"),
])
def test_face_values_rejects(args, match):
    with pytest.raises(ValueError, match=match):
        metrics.face_values(*(a[0] if isinstance(a, tuple) else a for a in args))


def test_relative_errors_rejects_length_mismatch():
    with pytest.raises(ValueError, match="same length"):
        metrics.relative_errors(np.ones((2, 3)), np.ones((3, 3)), np.ones(3))


def test_concentration_sets_the_worst_faces_apart():
    ref = np.ones((5, 3))
    test = ref.copy()
    test[2] *= 1.5                 # one face 50 % off, the others 1 % off
    test[[0, 1, 3, 4]] *= 1.01
    c = metrics.concentration(test, ref, np.ones(5), top=1)
    assert list(c["faces"]) == [2]
    assert c["area"] == pytest.approx(0.2)
    assert c["rms_rest"] == pytest.approx(0.01)
    assert c["share"] == pytest.approx(0.25 / (0.25 + 4 * 1e-4))


def test_reference_noise_two_seeds_is_half_their_difference():
    a = np.ones((3, 3)) * np.array([[1.0], [2.0], [4.0]])
    b = a * np.array([[1.1], [0.8], [1.0]])
    area = np.array([1.0, 1.0, 2.0])
    got = metrics.reference_noise([a, b], area)
    mean = (a + b)[:, 0] / 2
    rel = np.abs(a - b)[:, 0] / 2 / mean
    w = area / area.sum()
    assert got["rms"] == pytest.approx(np.sqrt(np.sum(w * rel ** 2)), rel=1e-12)
    assert got["seeds"] == 2 and got["faces"] == 3


def test_reference_noise_falls_as_one_over_root_n():
    # Seeds drawn with a known per-face noise sigma: the estimate of the mean's noise is
    # sigma / sqrt(N) (to the sampling error of the variance over 20000 faces, ~1 %).
    rng = np.random.default_rng(7)
    sigma = 0.05
    for n in (2, 8):
        seeds = 1.0 + sigma * rng.standard_normal((n, 20000, 1)) * np.ones((1, 1, 3))
        got = metrics.reference_noise(seeds, np.ones(20000))
        assert got["rms"] == pytest.approx(sigma / np.sqrt(n), rel=0.03)
    with pytest.raises(ValueError, match="N >= 2"):
        metrics.reference_noise(np.ones((1, 4, 3)), np.ones(4))
