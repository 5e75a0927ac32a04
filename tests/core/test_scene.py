"""Scene validation, derived geometry and the procedural sample scenes."""

import numpy as np
import pytest

from core import SceneError, make_scene, scene_from_polygons
from bench import scenes as samples

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
RHO = [[0.5, 0.5, 0.5]]
LE = [[1.0, 1.0, 1.0]]


def square_scene(**overrides):
    args = dict(vertices=SQUARE, corner_verts=[0, 1, 2, 3], face_starts=[0], face_sizes=[4],
                face_materials=[0], reflectance=RHO, emission=LE)
    args.update(overrides)
    return make_scene(**args)


def test_square_normal_and_area():
    s = square_scene()
    np.testing.assert_allclose(s.face_normals, [[0, 0, 1]])
    np.testing.assert_allclose(s.face_areas, [1.0])
    assert s.face_valid.all() and s.faces_dropped == 0


def test_concave_ngon_area_and_normal_far_from_origin():
    # An L-shaped hexagon (area 3) translated 1e4 m away: centring keeps the digits.
    pts = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float) + 1e4
    s = scene_from_polygons(pts, [range(6)], [0], RHO, LE)
    np.testing.assert_allclose(s.face_areas, [3.0], rtol=1e-12)
    np.testing.assert_allclose(s.face_normals, [[0, 0, 1]], atol=1e-12)


def test_arrays_are_read_only_and_inputs_not_mutated():
    verts = SQUARE.copy()
    s = square_scene(vertices=verts)
    with pytest.raises(ValueError):
        s.vertices[0, 0] = 5.0
    verts[0, 0] = 9.0
    assert s.vertices[0, 0] == 0.0


def test_degenerate_faces_are_dropped_and_counted():
    pts = np.vstack([SQUARE, [[0, 0, 0], [1, 0, 0], [2, 0, 0]]])  # a collinear triangle
    s = scene_from_polygons(pts, [[0, 1, 2, 3], [4, 5, 6], [0, 0, 1]], [0, 0, 0], RHO, LE)
    assert s.faces_dropped == 2
    assert s.face_valid.tolist() == [True, False, False]
    assert np.isfinite(s.face_normals).all() and np.isfinite(s.face_areas).all()


def test_face_label_names_object_and_local_index():
    pts = np.vstack([SQUARE, SQUARE + [0, 0, 1]])
    s = scene_from_polygons(pts, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 0], RHO, LE,
                            face_objects=[0, 1], object_names=["Floor", "Lamp"])
    assert s.face_label(1) == 'face 0 of object "Lamp"'


@pytest.mark.parametrize("overrides, message", [
    (dict(vertices=[[0, 0]]), r"vertices must have shape \(n, 3\); got \(1, 2\)"),
    (dict(vertices=np.array([[0, 0, 0], [1, 0, 0], [1, np.nan, 0], [0, 1, 0]])),
     r"vertices contain NaN or inf: vertex 2"),
    (dict(corner_verts=[0, 1, 2, 7]), r"corner_verts\[3\] = 7 is out of range for 4 vertices"),
    (dict(corner_verts=[0, 1, 2.5, 3]), r"corner_verts must hold integers; got 2.5 at index 2"),
    (dict(face_sizes=[2], face_starts=[0]), r"face_sizes must be >= 3: face 0 of object"),
    (dict(face_starts=[1]), r"face_starts\[0\] = 1 with 4 corners runs past the 4 corners"),
    (dict(face_materials=[3]), r"face_materials\[0\] = 3 is out of range for 1 materials"),
    (dict(face_materials=[0, 0]), r"face_materials must have one entry per face \(1\); got 2"),
    (dict(reflectance=[[0.5, 1.0, 0.5]]), r"reflectance must lie in \[0, 1\).*material 0"),
    (dict(reflectance=[[0.5, -0.1, 0.5]]), r"reflectance must lie in \[0, 1\)"),
    (dict(reflectance=[[0.5, np.inf, 0.5]]), r"reflectance contains NaN or inf: material 0"),
    (dict(emission=[[1.0, -1.0, 0.0]]), r"emission must be >= 0: material 0"),
    (dict(emission=[[0.0, 0.0, 0.0]]), r"the scene has no emitter"),
    (dict(emission=[[1, 1, 1], [1, 1, 1]]), r"emission must have one row per material \(1\); got 2"),
    (dict(vertices=np.zeros((0, 3)), corner_verts=[], face_starts=[], face_sizes=[],
          face_materials=[]), r"the scene is empty"),
    (dict(face_objects=[2], object_names=["a"]), r"face_objects\[0\] = 2 is out of range for 1 object"),
    (dict(back_reflectance=[[0.5, 1.5, 0.5]]), r"back_reflectance must lie in \[0, 1\).*material 0"),
    (dict(back_emission=[[0.0, -2.0, 0.0]]), r"back_emission must be >= 0: material 0"),
    (dict(back_emission=[[0, 0, 0], [0, 0, 0]]),
     r"back_emission must have one row per material \(1\); got 2"),
    (dict(back_reflectance=[[np.nan, 0, 0]]), r"back_reflectance contains NaN or inf: material 0"),
])
def test_refused_inputs_name_the_argument(overrides, message):
    with pytest.raises(SceneError, match=message):
        square_scene(**overrides)


def test_emitter_on_dropped_face_only_is_no_emitter():
    pts = np.vstack([SQUARE, [[0, 0, 0], [1, 0, 0], [2, 0, 0]]])
    with pytest.raises(SceneError, match="no emitter"):
        scene_from_polygons(pts, [[0, 1, 2, 3], [4, 5, 6]], [0, 1], [[0.5] * 3, [0.5] * 3],
                            [[0.0] * 3, [1.0] * 3])


def test_scene_error_is_a_value_error():
    with pytest.raises(ValueError):
        square_scene(face_materials=[5])


def _face_centroids(s):
    corners, faces = s.face_corner_indices()
    c = np.zeros((s.n_faces, 3))
    np.add.at(c, faces, s.vertices[s.corner_verts[corners]])
    return c / s.face_sizes[:, None]


@pytest.mark.parametrize("build", [lambda: samples.unit_cube(3), lambda: samples.furnace_box(n=2)])
def test_cube_normals_point_inward_and_area_is_six(build):
    s = build()
    assert s.face_areas.sum() == pytest.approx(6.0, rel=1e-12)
    inward = np.einsum("ij,ij->i", s.face_normals, 0.5 - _face_centroids(s))
    assert (inward > 0).all()


def test_room_with_boxes_hits_requested_size_and_orients_faces():
    s = samples.room_with_boxes(2000)
    assert 0.9 * 2000 <= s.n_faces <= 1.1 * 2000
    c = _face_centroids(s)
    for o, name in enumerate(s.object_names):
        n = s.face_normals[s.face_objects == o]
        if name.startswith("wall") or name in ("floor", "ceiling"):
            to_centre = np.array([3.0, 2.0, 1.5]) - c[s.face_objects == o]
            assert (np.einsum("ij,ij->i", n, to_centre) > 0).all(), name


def test_cornell_box_geometry_matches_published_data():
    s = samples.cornell_box()
    light = s.face_materials == s.material_names.index("light")
    # The light is 130 x 105 mm and faces down.
    assert s.face_areas[light].sum() == pytest.approx(0.130 * 0.105, rel=1e-9)
    np.testing.assert_allclose(s.face_normals[light], [[0, 0, -1]])
    # Red wall on the camera's left: the camera looks along -Y, so its left is +X.
    red = s.face_materials == s.material_names.index("red")
    green = s.face_materials == s.material_names.index("green")
    c = _face_centroids(s)
    assert c[red, 0].min() > 0.5 and c[green, 0].max() < 0.01
    # Walls face the room, and the floor is the published 552.8/549.6 x 559.2 mm trapezoid.
    floor = s.object_names.index("floor")
    assert s.face_areas[s.face_objects == floor].sum() == pytest.approx(
        0.5 * (0.5528 + 0.5496) * 0.5592, rel=1e-9)


def test_cornell_light_is_warm_white():
    rgb = samples.cornell_light_radiance(peak=1.0)
    assert rgb.max() == pytest.approx(1.0)
    assert rgb[0] > rgb[1] > rgb[2] > 0


def test_back_materials_default_to_the_front():
    s = square_scene()
    rho, le = s.back_materials()
    assert rho is s.reflectance and le is s.emission
    one_sided = square_scene(back_reflectance=[[0.0] * 3], back_emission=[[0.0] * 3])
    rho, le = one_sided.back_materials()
    np.testing.assert_array_equal(rho, 0.0)
    np.testing.assert_array_equal(le, 0.0)


def test_back_emission_alone_counts_as_an_emitter():
    s = square_scene(emission=[[0.0] * 3], back_emission=[[2.0] * 3])
    assert s.back_emission[0, 0] == 2.0
