"""Receiver elements: the final gather sees the light's gradient across a patch, not its mean.

The oracle is a scene whose answer is an integral computed here independently: a ceiling lit only
by the back of a luminaire panel hung 5 cm below it, and a near-black floor. The floor's
irradiance is the panel's direct light (closed form) plus one bounce off the ceiling (quadrature
over the ceiling, with the panel's shadow).
"""

import importlib

import numpy as np
import pytest

from bench.scenes import furnace_box
from builders import grid
from core import BakeSettings, SettingsError, bake, relight, scene_from_polygons
from core.elements import make_elements
from core.exact import point_polygon_form_factor
from core.patches import make_patches

H, DROP, LE, RHO_CEILING, RHO_FLOOR = 1.5, 0.05, 10.0, 0.8, 1e-3
PANEL = (0.75, 1.25)            # x and y extent: its edges cut the 0.5 m ceiling faces in half

#: Floor points (shared vertices of every mesh used) where the bake is compared.
POINTS = np.array([[a, b, 0.0] for a in (0.5, 1.0, 1.5) for b in (0.5, 1.0, 1.5)]
                  + [[0.0, 1.0, 0.0]])


def _panel_corners():
    p0, p1 = PANEL
    z = H - DROP
    return np.array([[p0, p0, z], [p0, p1, z], [p1, p1, z], [p1, p0, z]])


def _grids_scene(parts, reflectance, emission, **kw):
    """A scene of ``grid`` parts (origin, a, b, n, material), one material per part."""
    verts, polys, mats, off = [], [], [], 0
    for origin, a, b, k, m in parts:
        v, q = grid(origin, a, b, k)
        verts.append(v)
        polys += (np.asarray(q) + off).tolist()
        mats += [m] * len(q)
        off += len(v)
    return scene_from_polygons(np.vstack(verts), polys, mats, reflectance, emission, **kw)


def hung_panel(n=4):
    """2 x 2 m floor and ceiling (n x n faces), a 0.5 m panel hung under the ceiling, no walls."""
    p0, p1 = PANEL
    parts = [((0, 0, 0), (2, 0, 0), (0, 2, 0), n, 0),                 # floor, normal +z
             ((0, 0, H), (0, 2, 0), (2, 0, 0), n, 1),                 # ceiling, normal -z
             ((p0, p0, H - DROP), (0, p1 - p0, 0), (p1 - p0, 0, 0), 1, 2)]   # panel, -z
    return _grids_scene(parts, [[RHO_FLOOR] * 3, [RHO_CEILING] * 3, [0.0] * 3],
                        [[0.0] * 3, [0.0] * 3, [LE] * 3])


def oracle_irradiance(x, cells=600):
    """Floor irradiance at points ``x`` (k, 3): direct + one bounce off the ceiling.

    The ceiling's radiance at y is rho/pi * pi Le F(y -> panel back) (closed form); the floor
    point sees it where the segment misses the panel. Midpoint quadrature on cells x cells: the
    answer moves by 0.5 % from 400 to 800 cells.
    """
    panel = _panel_corners()
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    direct = np.pi * LE * point_polygon_form_factor(x, up, panel[None])[:, 0]
    h = 2.0 / cells
    g = (np.arange(cells) + 0.5) * h
    y = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    y = np.c_[y, np.full(len(y), H)]
    down = np.tile([0.0, 0.0, -1.0], (len(y), 1))
    ceiling = RHO_CEILING * LE * point_polygon_form_factor(y, down, panel[None])[:, 0]
    out = direct.copy()
    for k, xi in enumerate(x):        # one vectorised quadrature per point (ten points)
        d = y - xi
        r2 = np.einsum("ij,ij->i", d, d)
        hit = xi[:2] + ((H - DROP - xi[2]) / d[:, 2])[:, None] * d[:, :2]
        seen = ~np.all((hit > PANEL[0]) & (hit < PANEL[1]), axis=1)
        out[k] += np.sum(seen * ceiling * d[:, 2] ** 2 / r2 ** 2) * h * h
    return out


def floor_irradiance(scene, result, points=POINTS):
    """pi L / rho at ``points``, from the corner colours of the floor corners there."""
    pos = np.asarray(scene.vertices)[np.asarray(scene.corner_verts)]
    face = np.repeat(np.arange(len(scene.face_sizes)), scene.face_sizes)
    floor = np.asarray(scene.face_materials)[face] == 0
    out = []
    for x in points:
        at = floor & np.all(np.abs(pos - x) < 1e-9, axis=1)
        out.append(np.pi * result.corner_colours[at, 0].mean() / RHO_FLOOR)
    return np.array(out)


@pytest.fixture(scope="module")
def truth():
    return oracle_irradiance(POINTS)


def test_without_elements_the_floor_sees_half_hidden_patches_at_their_bright_mean(truth):
    scene = hung_panel(4)
    res = bake(scene, BakeSettings(patch_size=0.5, element_levels=0, emitter_levels=0))
    err = floor_irradiance(scene, res) / truth - 1
    # The ceiling faces under the panel's edges are bright over the panel and dark outside it;
    # the floor sees only their dark half but reads their mean: about +37 % at every point.
    assert np.all(err > 0.2)


def test_near_emitter_split_alone_brings_the_floor_to_the_oracle(truth):
    # The radiosity mesh's other remedy: the solve patches near the panel are split until each is
    # at most 4 x its distance to it, so the ceiling faces under the panel's edge are small.
    # Tolerance as below for two element levels (hemicube aliasing ~2 %, quadrature 0.5 %).
    scene = hung_panel(4)
    res = bake(scene, BakeSettings(patch_size=0.5, element_levels=0))
    err = floor_irradiance(scene, res) / truth - 1
    assert np.max(np.abs(err)) < 0.04
    assert res.report["patches"] > 3 * 16 + 1       # the ceiling was split: more than the input


@pytest.mark.parametrize("levels, mean_tol, max_tol", [(1, 0.06, 0.08), (2, 0.02, 0.04)])
def test_elements_bring_the_floor_to_the_oracle(truth, levels, mean_tol, max_tol):
    # Tolerances: the hemicube's aliasing at R = 64 moves a point's gather by about 2 %, the
    # quadrature is good to 0.5 %; one level halves the elements under the panel's edge, two
    # quarter them (the remaining error is the light's gradient within an element).
    scene = hung_panel(4)
    res = bake(scene, BakeSettings(patch_size=0.5, element_levels=levels,
                                   element_threshold=0.3, emitter_levels=0,
                                   element_near_threshold=0))    # the general step alone
    err = floor_irradiance(scene, res) / truth - 1
    assert abs(err.mean()) < mean_tol
    assert np.max(np.abs(err)) < max_tol
    info = res.report["elements"]
    assert len(info["levels"]) == levels
    assert info["elements"] == res.report["patches"] + 3 * sum(s["split"] for s in info["levels"])
    # Only where the light changes: the floor (lit smoothly) and the far ceiling are not split.
    assert info["levels"][0]["split"] < res.report["patches"] / 2


#: A floor (near-black) and a wall at x = 0 (RHO_WALL) lit by a panel facing the wall from
#: x = WALL_GAP, y 0.5 to 1.5 m, z 0.5 to 1.2 m; nothing else reflects. The wall is brightest
#: in front of the panel and darker towards the floor, across its bottom 0.5 m face.
WALL_GAP, RHO_WALL = 0.3, 0.8
WALL_PANEL = np.array([[WALL_GAP, 0.5, 0.5], [WALL_GAP, 1.5, 0.5], [WALL_GAP, 1.5, 1.2],
                       [WALL_GAP, 0.5, 1.2]])
#: Floor points next to the wall (vertices of the floor's 16 x 16 faces).
WALL_POINTS = np.array([[0.125, b, 0.0] for b in (0.75, 1.0, 1.25)])


def lit_wall(**kw):
    """The floor (16 x 16 faces) and the wall (4 x 4 faces of 0.5 m) of WALL_PANEL (``kw``:
    :func:`core.scene_from_polygons`'s)."""
    parts = [((0, 0, 0), (2, 0, 0), (0, 2, 0), 16, 0),                 # floor, +z
             ((0, 0, 0), (0, 2, 0), (0, 0, 2), 4, 1),                  # wall, +x
             (WALL_PANEL[0], WALL_PANEL[3] - WALL_PANEL[0], WALL_PANEL[1] - WALL_PANEL[0], 1,
              2)]                                                        # panel, -x
    return _grids_scene(parts, [[RHO_FLOOR] * 3, [RHO_WALL] * 3, [0.0] * 3],
                        [[0.0] * 3, [0.0] * 3, [LE] * 3], **kw)


def wall_oracle(x, cells=800):
    """Floor irradiance at ``x`` (k, 3), x < WALL_GAP: the panel's direct light (closed form)
    plus one bounce off the wall, whose radiance is rho Le F(w -> panel) (closed form); a floor
    point nearer the wall than the panel sees all of the wall. Midpoint quadrature on the wall:
    0.1 % from 400 to 800 cells."""
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    out = np.pi * LE * point_polygon_form_factor(x, up, WALL_PANEL[None])[:, 0]
    h = 2.0 / cells
    g = (np.arange(cells) + 0.5) * h
    w = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    w = np.c_[np.zeros(len(w)), w]
    lw = RHO_WALL * LE * point_polygon_form_factor(w, np.tile([1.0, 0.0, 0.0], (len(w), 1)),
                                                   WALL_PANEL[None])[:, 0]
    for k, xi in enumerate(x):        # one vectorised quadrature per point (three points)
        d = w - xi
        r2 = np.einsum("ij,ij->i", d, d)
        out[k] += np.sum(lw * d[:, 2] * -d[:, 0] / r2 ** 2) * h * h
    return out


@pytest.mark.parametrize("near", [0.15, 0.0])
def test_near_elements_bring_the_floor_at_a_wall_to_the_oracle(near):
    # A floor point 12.5 cm from the wall sees the wall's bottom strip under the largest solid
    # angle; the wall's bottom face (0 to 0.5 m) is darker there than its mean. With the
    # general step blind (0.9), only the near step (core.criteria.near_surfaces) splits it.
    # Tolerance: hemicube aliasing ~2 % at R = 64, quadrature 0.1 %; without the near step the
    # floor reads the face's brighter mean (measured +5 to +7 %).
    scene = lit_wall()
    res = bake(scene, BakeSettings(patch_size=0.5, element_levels=2, element_threshold=0.9,
                                   emitter_levels=0, element_near_threshold=near))
    err = floor_irradiance(scene, res, WALL_POINTS) / wall_oracle(WALL_POINTS) - 1
    if near:
        assert np.max(np.abs(err)) < 0.025, err
        assert len(res.report["elements"]["levels"]) == 3      # the near round after the two
    else:
        assert np.all(err > 0.03), err


def test_near_surfaces_are_corners_and_contacts_not_coplanar_or_distant_patches():
    from core.criteria import near_surfaces
    # A floor (2 x 2 faces of 1 m), a wall on its edge x = 0, a coplanar floor far away, and
    # a board floating 3 m above the floor's far half.
    verts, polys = [], []
    for origin, a, b in [((0, 0, 0), (2, 0, 0), (0, 2, 0)), ((0, 0, 0), (0, 2, 0), (0, 0, 2)),
                         ((10, 0, 0), (2, 0, 0), (0, 2, 0)), ((1, 0, 3), (1, 0, 0), (0, 2, 0))]:
        v, q = grid(origin, a, b, 2)
        polys += (np.asarray(q) + sum(len(x) for x in verts)).tolist()
        verts.append(v)
    scene = scene_from_polygons(np.vstack(verts), polys, [0] * (len(polys) - 1) + [1],
                                [[0.5] * 3] * 2, [[0.0] * 3, [1.0] * 3])
    patches = make_patches(scene, 1.0)
    near = near_surfaces(patches)
    c = patches.centres
    floor = (c[:, 2] == 0) & (c[:, 0] < 5)
    # Floor next to the wall (x 0 to 1) and the wall's bottom row are near; the floor's far
    # half, the wall's top row, the distant floor and the high board are not.
    np.testing.assert_array_equal(near[floor], c[floor, 0] < 1)
    wall = c[:, 0] == 0
    np.testing.assert_array_equal(near[wall], c[wall, 2] < 1)
    assert not near[c[:, 0] > 5].any() and not near[c[:, 2] == 3].any()


def test_uniform_light_makes_no_elements():
    # The white furnace: every patch has the same radiance, so nothing is split and the
    # answer stays L = Le / (1 - rho).
    scene = furnace_box(rho=0.5, le=1.0, n=3)
    res = bake(scene, BakeSettings(patch_size=1.0, resolution=32, element_levels=2))
    assert res.report["elements"]["levels"] == []
    assert res.report["elements"]["elements"] == res.report["patches"]
    np.testing.assert_allclose(res.corner_colours, 2.0, rtol=2e-3)


def test_make_elements_with_no_level_is_the_patches():
    scene = hung_panel(2)
    patches = make_patches(scene, 1.0)
    L = np.random.default_rng(0).uniform(0.1, 1.0, (2 * patches.areas.size, 3))
    el = make_elements(scene, patches, L, levels=0, threshold=0.3, crease_angle=30.0)
    assert el.patches is patches and el.computed.size == 0
    np.testing.assert_array_equal(el.node_radiance(scene, L), L)
    with pytest.raises(ValueError, match=r"node_radiance must have shape \(2P, 3\)"):
        make_elements(scene, patches, L[:-1], levels=1, threshold=0.3, crease_angle=30.0)
    with pytest.raises(ValueError, match="levels must be an int >= 0; got -1"):
        make_elements(scene, patches, L, levels=-1, threshold=0.3, crease_angle=30.0)


def test_relight_keeps_the_elements_and_computes_no_form_factor(monkeypatch):
    scene = hung_panel(4)
    res = bake(scene, BakeSettings(patch_size=0.5, element_levels=2))
    hemicube = importlib.import_module("core.hemicube")
    with monkeypatch.context() as m:
        for name in ("hemicube_rows", "point_rows"):
            m.setattr(hemicube, name, lambda *a, **k: pytest.fail("form factors recomputed"))
        same = relight(res)
        double = relight(res, emission=2 * np.asarray(scene.emission))
    np.testing.assert_allclose(same.corner_colours, res.corner_colours, rtol=1e-12)
    # Radiosity is linear in the emission: same elements, twice the light.
    np.testing.assert_allclose(double.corner_colours, 2 * res.corner_colours, rtol=1e-6)
    assert same.report["elements"] == res.report["elements"]


def test_progress_stays_monotone_with_elements():
    seen = []
    bake(hung_panel(4), BakeSettings(patch_size=0.5, element_levels=2),
         progress=lambda f, m: seen.append(f))
    assert all(b >= a for a, b in zip(seen, seen[1:]))
    assert seen[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("kwargs, message", [
    (dict(element_levels=4), r"element_levels must be an integer in \[0, 3\]; got 4"),
    (dict(element_levels=1.0), r"element_levels must be an integer in \[0, 3\]; got 1.0"),
    (dict(element_threshold=0.0), r"element_threshold must be a number in \(0, 1\); got 0.0"),
    (dict(element_threshold=1.0), r"element_threshold must be a number in \(0, 1\); got 1.0"),
    (dict(element_near_threshold=1.0),
     r"element_near_threshold must be a number in \[0, 1\); got 1.0"),
])
def test_element_settings_are_validated(kwargs, message):
    with pytest.raises(SettingsError, match=message):
        BakeSettings(**kwargs)


@pytest.mark.parametrize("sky", ["uniform", "cie_overcast"])
def test_late_elements_take_the_world_from_their_gather_against_the_elements(sky):
    # The last round's new elements next to another surface are gathered only against the
    # elements (core.elements.Elements.late): a gather over the solved patches would only start
    # their sweeps. Their share of the world (uniform: world x (1 - row sum); a directional
    # sky: what the hemicube's open pixels see) comes from that second hemicube, and must be
    # what a gather over the solved patches at the same points sees. Tolerance: one geometry
    # drawn two ways (elements, far patches whole) under independent random rotations at
    # R = 64, each ~1 % (measured: 1.5-2.1 % at most, means 0.05-0.2 %).
    from core.hemicube import point_rows
    scene = lit_wall(world=[0.4, 0.4, 0.4]) if sky == "uniform" else lit_wall()
    res = bake(scene, BakeSettings(patch_size=0.5, element_levels=2, element_threshold=0.9,
                                   emitter_levels=0, sky="world" if sky == "uniform" else sky))
    state = res._state
    el, direct = state.gather.elements, state.direct
    pos = np.flatnonzero(el.late)
    assert pos.size > 50
    assert np.isnan(el.rows.row_sums[pos]).all()           # no row over the solved patches
    assert np.isin(pos, el.near).all()
    c, n = el.points()
    c, n = c[pos], n[pos]
    light = None if direct.sky is None else np.zeros((pos.size, 3))
    rows = point_rows(state.patches, c, n, resolution=64, rotate=True, rng=7, sky=direct.sky,
                      sky_out=light)
    lights = direct.incident(c, n)
    want = direct.extra(c, n, rows.sum(axis=1), sky=light) - lights
    got = el.direct[pos] - lights
    assert want.min() > 0.01                               # the world's share is there
    rel = got / want - 1
    assert np.abs(rel).max() < 0.04 and abs(rel.mean()) < 0.005, rel
