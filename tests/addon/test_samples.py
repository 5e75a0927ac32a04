"""The bundled samples are modelled as users model rooms and open framed on the room.

Oracles: the scripts' own geometry (a 6 x 4 x 3 m office, a 12 x 8 x 2.8 m apartment, the
published Cornell box), face counts of one polygon per surface, normals of the shell pointing into
the room, and the saved screens' 3D views looking through the scene camera.
"""

import os

import bpy
import numpy as np
import pytest

from conftest import ROOT

#: (file, room centre, most faces, shell objects): one polygon per wall/floor/ceiling side, boxes of
#: a few quads; the pre-meshed benchmark copies have thousands.
SAMPLES = [("office", (3.0, 2.0, 1.5), 100, ("Room", "AccentWall")),
           ("apartment", (6.0, 4.0, 1.4), 120, ("Shell", "AccentWall")),
           ("cornell_box", (0.278, -0.28, 0.274), 30, ("Floor", "Back_Wall", "Ceiling"))]


@pytest.mark.parametrize("name, centre, most, shell", SAMPLES)
def test_sample_is_coarse_faces_in_and_opens_in_camera_view(package, name, centre, most, shell):
    path = os.path.join(ROOT, "sample_blends", f"{name}.blend")
    bpy.ops.wm.open_mainfile(filepath=path, load_ui=True)
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    faces = sum(len(o.data.polygons) for o in meshes)
    assert 0 < faces <= most
    bench = os.path.join(ROOT, "bench", "blends", f"{name}.blend")
    assert os.path.exists(bench), "the benchmark's pre-meshed copy must stay in bench/blends"
    for obj_name in shell:
        obj = bpy.data.objects[obj_name]
        mw = np.array(obj.matrix_world)
        for poly in obj.data.polygons:
            c = mw[:3, :3] @ np.array(poly.center) + mw[:3, 3]
            n = mw[:3, :3] @ np.array(poly.normal)
            assert np.dot(n, np.array(centre) - c) > 0, f"{obj_name} face {poly.index} faces out"
    assert bpy.context.scene.camera is not None
    views = [space.region_3d.view_perspective for screen in bpy.data.screens
             for area in screen.areas if area.type == "VIEW_3D"
             for space in area.spaces if space.type == "VIEW_3D"]
    assert views and all(v == "CAMERA" for v in views)
