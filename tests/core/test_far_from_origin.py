"""Far from the origin: regressions that longer runs of the fuzz (tests/core/test_fuzz.py, more
examples than CI runs) found where float32 rounding of the coordinates meets the cuts.

Oracle: the white furnace, every surface emitting Le and reflecting rho: every written corner
reads Le / (1 - rho) (FURNACE_RTOL, test_fuzz's: the solver's tolerance and float32 rows).
"""

import numpy as np
import pytest

from core import BakeSettings, bake

from test_fuzz import FURNACE_RTOL, R, _furnace, _l_room_with_a_box, _Polys


def _octagon_room_733m():
    """test_white_furnace_radiosity_mesh's scene that a longer run (150 examples) found: an
    8-gon room, two boxes on the floor, a ceiling panel; moved 733.69 m along x."""
    plan = np.array([[1.549862124900326, 2.5686431036248387], [-0.6265980088632651,
                     2.8748553657242577], [-1.2622064772118446, 0.8104534588022096],
                     [-2.101500566157037, -0.9843958328140129], [-1.1485988285141382,
                     -0.9647386854148379], [0.19311841858983975, -0.9811754564813366],
                     [0.9787505171745173, -0.6284482085110996],
                     [1.1567334699171985, 0.05739949755468778]])
    h = 3.144868576544123
    polys = _Polys()
    polys.room(plan, h)
    polys.box((-0.4965695524982482, -0.41688030784901414, 0.0),
              (-0.15213881189488798, 0.15686756962466492, 0.9149001494589819), 1)
    polys.box((0.1815308782337277, -0.3976421510848759, 0.0),
              (0.3881893225957438, 0.03814558290674391, 0.971544560726769), 1)
    r = 0.2066584443620161
    polys.add([[-r, -r, 2.804920967077822], [-r, r, 2.804920967077822],
               [r, r, 2.804920967077822], [r, -r, 2.804920967077822]], 2)
    return polys


@pytest.mark.parametrize("shadow_cuts", [False, True])
def test_regression_furnace_733m_from_the_origin(shadow_cuts):
    """At 733 m a float32 rounding of the coordinates is 0.35 mm, which the conformity pass
    (core.hierarchy) allows between a point and an edge it lies on. A contact cut crossed a
    patch edge 0.1 mm from a corner, that point was taken as lying on the neighbours' edges,
    and zero-area triangles' corners read 2.23 for 8.66 (18 corners; 23 with shadow cuts).
    The conformity pass now takes a point as on an edge within float32 rounding only inside a
    3-degree lens from the edge's ends (core.hierarchy.ON_EDGE_SLANT), and shadow lines cut
    only the patches they run into (core.contacts._crossed)."""
    rho, le = 0.7422501474869286, 2.2330048150040147
    scene = _furnace(_octagon_room_733m(), rho, le, 1.0, (733.6931775714288, 0.0, 0.0))
    result = bake(scene, BakeSettings(output_mode="mesh", patch_size=1.3460178887089005,
                                      resolution=R, element_levels=1,
                                      min_element=0.3365044721772251, exact_direct="off",
                                      vertex_budget=300, shadow_cuts=shadow_cuts))
    np.testing.assert_allclose(result.output.corner_colours, le / (1 - rho), rtol=FURNACE_RTOL)


def test_regression_shadow_lines_leave_rounding_slivers_whole():
    """Found by a longer run of test_white_furnace_radiosity_mesh with standing boxes and shadow
    cuts: the L room at a tenth of its size, 58 m from the origin. Ear clipping leaves 6
    patches of no area along the floor's diagonal (rounding: 1.6e-19 m^2); a shadow line from
    the box's corner cut one, and its pieces had no normal, which stopped the bake
    (ValueError in the hemicube). core.contacts._crossed now cuts no patch without area."""
    scene = _furnace(_l_room_with_a_box(), 0.0, 1.0, 0.1, (0.0, 578.5, 0.0))
    result = bake(scene, BakeSettings(output_mode="mesh", patch_size=0.1, resolution=R,
                                      element_levels=0, min_element=0.025, exact_direct="off",
                                      vertex_budget=300, shadow_cuts=True))
    assert result.report["contacts"]["shadow_cuts"] > 0
    np.testing.assert_allclose(result.output.corner_colours, 1.0, rtol=FURNACE_RTOL)
