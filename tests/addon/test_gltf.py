"""A baked object through Blender's bundled glTF exporter keeps its colours (COLOR_0).

This is how users take a bake into a game engine or onto the web: the ``Radiosity`` attribute is
the active colour, so the exporter's "Active" vertex colour mode writes it as COLOR_0.
"""

import json
import struct

import bpy
import numpy as np

from conftest import PACKAGE
from helpers import box, material, mesh_object, square
from outmesh_fake import smooth_colour, split_output

write = PACKAGE.radiosity_addon.write
extract_mod = PACKAGE.radiosity_addon.extract

#: glTF accessor component types (the spec's numbers) -> NumPy dtype and normalisation divisor.
COMPONENTS = {5126: (np.float32, 1.0), 5123: (np.uint16, 65535.0), 5121: (np.uint8, 255.0)}
#: Colours may be quantised to 8 bits by the exporter; positions are float32.
COLOUR_ATOL = 1.0 / 255.0 + 1e-5
POSITION_ATOL = 1e-5


def read_glb(path):
    """(JSON dict, binary chunk bytes) of a .glb file."""
    with open(path, "rb") as fh:
        data = fh.read()
    magic, _version, _length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67  # "glTF"
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A  # "JSON"
    doc = json.loads(data[20:20 + json_len])
    offset = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, offset)
    assert bin_type == 0x004E4942  # "BIN"
    return doc, data[offset + 8:offset + 8 + bin_len]


def accessor(doc, blob, index):
    """(count, width) float64 array of a glTF accessor (normalised integers scaled to [0, 1])."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype, scale = COMPONENTS[acc["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", width * np.dtype(dtype).itemsize)
    rows = [np.frombuffer(blob, dtype=dtype, count=width, offset=start + i * stride)
            for i in range(acc["count"])]
    out = np.array(rows, dtype=np.float64).reshape(acc["count"], width)
    return out / scale if acc.get("normalized") or scale != 1.0 else out


def test_gltf_export_writes_the_bake_as_color_0(package, tmp_path):
    lv, lf = square(1.0, z=3.0, down=True)
    mesh_object("Lamp", lv, lf, material("lamp", (0, 0, 0), emission=(1, 1, 1), strength=5.0,
                                         kind="emission"))
    v, f = box(2.0)
    room = mesh_object("Room", v, f, material("grey"), location=(0.3, -0.2, 1.0))
    ext = extract_mod.extract(bpy.context.evaluated_depsgraph_get())
    write.write_mesh({o.name: o for o in bpy.context.scene.objects}, ext.parts,
                     split_output(ext.arrays))
    for obj in bpy.context.scene.objects:
        obj.select_set(obj is room)
    path = str(tmp_path / "room.glb")
    result = bpy.ops.export_scene.gltf(filepath=path, export_format="GLB", use_selection=True,
                                       export_vertex_color="ACTIVE", export_yup=True)
    assert result == {"FINISHED"}
    doc, blob = read_glb(path)
    (node,) = [n for n in doc["nodes"] if n.get("name") == "Room"]
    prims = doc["meshes"][node["mesh"]]["primitives"]
    positions, colours = [], []
    for prim in prims:
        attrs = prim["attributes"]
        assert "COLOR_0" in attrs
        pos = accessor(doc, blob, attrs["POSITION"])
        col = accessor(doc, blob, attrs["COLOR_0"])
        assert col.shape[0] == pos.shape[0]
        positions.append(pos)
        colours.append(col[:, :3])
    pos = np.concatenate(positions)
    col = np.concatenate(colours)
    # Every baked corner is exported (a vertex per distinct corner): 24 faces x 4 corners of a
    # 2 x 2 split cube, merged where position, normal, UV and colour agree -- at least the 26
    # baked vertices, at most the 96 corners.
    assert 26 <= pos.shape[0] <= 96
    # Y-up: glTF (x, y, z) = Blender (x, z, -y), in object space; back to world for the oracle.
    obj_space = np.c_[pos[:, 0], -pos[:, 2], pos[:, 1]]
    mw = np.array(room.matrix_world)
    world = obj_space @ mw[:3, :3].T + mw[:3, 3]
    baked = np.array([vv.co for vv in room.data.vertices])
    gap = np.linalg.norm(obj_space[:, None] - baked[None], axis=2).min(axis=1)
    assert gap.max() < POSITION_ATOL
    np.testing.assert_allclose(col, smooth_colour(world), atol=COLOUR_ATOL)
