"""Cycles harness on tiny scenes with closed-form answers (needs bpy: run under .venv)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from bench.compare import cycles  # noqa: E402

#: Unit square 1 m above a point at its corner: point-to-parallel-rectangle form factor (Howell,
#: /work/shared/reference/form_factors.md, a = b = c = 1).
F_CORNER = 0.1385316060


def _arrays(polygons, vertices, face_materials, rho, emission, objects):
    sizes = np.array([len(p) for p in polygons])
    return {
        "vertices": np.asarray(vertices, float),
        "corner_verts": np.concatenate(polygons),
        "face_starts": np.concatenate([[0], np.cumsum(sizes)[:-1]]),
        "face_sizes": sizes,
        "face_materials": np.asarray(face_materials),
        "reflectance": np.asarray(rho, float),
        "emission": np.asarray(emission, float),
        "face_objects": np.asarray(objects),
        "object_names": tuple("o%d" % i for i in range(max(objects) + 1)),
        "material_names": tuple("m%d" % i for i in range(len(rho))),
    }


@pytest.fixture
def empty_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy.context.scene
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_back_lit_square_corners_and_emission(empty_scene):
    # Grey floor (rho 0.5) under an emitter of strength 2 whose normal points UP, away from the
    # floor: only its back face lights the floor. Every floor corner is below a corner of the
    # emitter: L = rho * E / pi = rho * Le * F_corner.
    v = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    arrays = _arrays([[0, 1, 2, 3], [4, 5, 6, 7]], v, [0, 1],
                     [[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]], [[0, 0, 0], [2.0, 1.0, 0.5]], [0, 1])
    cycles.build(arrays, empty_scene)
    got = cycles.extract(empty_scene)
    np.testing.assert_allclose(got["vertices"], arrays["vertices"])
    np.testing.assert_allclose(got["emission"], arrays["emission"])
    cc, seconds = cycles.bake(empty_scene, samples=512, seed=0)
    assert cc.shape == (8, 3) and seconds > 0
    expected = 0.5 * np.array([2.0, 1.0, 0.5]) * F_CORNER
    # 2 %: 512 samples of next-event estimation on a unit light give ~0.3 % noise per corner.
    np.testing.assert_allclose(cc[:4], np.tile(expected, (4, 1)), rtol=0.02)
    # The emitter's corners: its own emission, added by the harness (rho = 0 reflects nothing).
    np.testing.assert_allclose(cc[4:], np.tile([2.0, 1.0, 0.5], (4, 1)), rtol=1e-6)


def test_furnace_needs_the_reference_bounces(empty_scene):
    # Closed cube, every face rho 0.8 and emission 1: L = 1 / (1 - 0.8) = 5 everywhere. Cycles'
    # default of 4 diffuse bounces gives 1 + .8 + ... + .8^5 = 3.69 (b bounces = b + 1
    # reflections: the last path vertex still gathers direct light by next-event estimation).
    v = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    # Normals point into the box: Cycles bakes the front side.
    quads = [[1, 3, 2, 0], [6, 7, 5, 4], [4, 5, 1, 0], [3, 7, 6, 2], [2, 6, 4, 0], [5, 7, 3, 1]]
    arrays = _arrays(quads, v, [0] * 6, [[0.8] * 3], [[1.0] * 3], [0] * 6)
    cycles.build(arrays, empty_scene)
    cc, _ = cycles.bake(empty_scene, samples=64, seed=1)
    # 3 %: Russian roulette makes path throughputs noisy; 24 corners x 64 samples average it.
    assert cc.mean() == pytest.approx(5.0, rel=0.03)
    cc4, _ = cycles.bake(empty_scene, samples=64, seed=1, bounces=4)
    assert cc4.mean() == pytest.approx(sum(0.8 ** k for k in range(6)), rel=0.03)


def test_seeds_differ_and_samples_validated(empty_scene):
    v = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    arrays = _arrays([[0, 1, 2, 3], [7, 6, 5, 4]], v, [0, 1],
                     [[0.5] * 3, [0.0] * 3], [[0] * 3, [1.0] * 3], [0, 1])
    cycles.build(arrays, empty_scene)
    a, _ = cycles.bake(empty_scene, samples=4, seed=0)
    b, _ = cycles.bake(empty_scene, samples=4, seed=1)
    assert not np.array_equal(a[:4], b[:4])
    with pytest.raises(ValueError, match="samples"):
        cycles.bake(empty_scene, samples=0)
