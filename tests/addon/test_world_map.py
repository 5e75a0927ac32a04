"""A textured world rendered to an equirectangular radiance map (radiosity_addon.world_map).

Oracles: a uniform world (the map is its colour x strength everywhere), a world whose colour is
its own view direction (each texel against the direction field averaged over the texel by
quadrature in this file), and the data-blocks before and after (nothing is left behind).
"""

import importlib

import bpy
import numpy as np
import pytest

from conftest import PACKAGE

world_map = importlib.import_module(PACKAGE.__name__ + ".radiosity_addon.world_map")


def _world(name):
    world = bpy.data.worlds.new(name)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True              # always on (deprecated) in 5
    return world, world.node_tree


def _direction_world():
    """A world whose colour is (max(x, 0), max(y, 0), max(z, 0)) of the view direction."""
    world, nt = _world("Directions")
    bg = nt.nodes["Background"]
    coords = nt.nodes.new("ShaderNodeTexCoord")
    split = nt.nodes.new("ShaderNodeSeparateXYZ")
    join = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(coords.outputs["Generated"], split.inputs[0])
    for i, axis in enumerate("XYZ"):
        clip = nt.nodes.new("ShaderNodeMath")
        clip.operation = "MAXIMUM"
        clip.inputs[1].default_value = 0.0
        nt.links.new(split.outputs[axis], clip.inputs[0])
        nt.links.new(clip.outputs[0], join.inputs[i])
    nt.links.new(join.outputs[0], bg.inputs["Color"])
    return world


def _blocks():
    return {name: set(getattr(bpy.data, name).keys())
            for name in ("scenes", "objects", "cameras", "images", "worlds")}


def test_a_uniform_world_maps_to_its_colour_times_strength():
    world, nt = _world("Uniform")
    nt.nodes["Background"].inputs["Color"].default_value = (0.2, 0.5, 0.8, 1.0)
    nt.nodes["Background"].inputs["Strength"].default_value = 3.0
    before = _blocks()
    m, sun = world_map.world_map(world)
    assert sun is None
    assert m.shape == (world_map.MAP_SIZE // 2, world_map.MAP_SIZE, 3)
    # Float32 EXR of a constant: exact up to the float32 rounding of 0.2 x 3 etc.
    np.testing.assert_allclose(m, np.broadcast_to([0.6, 1.5, 2.4], m.shape), rtol=1e-5)
    assert _blocks() == before


#: Each texel is the mean of 64 samples a render pixel over 16 pixels: a direction component
#: varies by ~0.1 across a 5.6 degree texel, so the sampling noise is ~0.1 / sqrt(1024) = 0.003
#: (measured: 1.0e-3 at most, bpy 5.0 and 4.2).
DIRECTION_ATOL = 0.003


def test_each_texel_is_the_mean_of_the_world_over_its_directions():
    m, sun = world_map.world_map(_direction_world())
    assert sun is None
    h, w = m.shape[:2]
    # Quadrature: 16 x 16 points per texel, weighted by their solid angle.
    k = 16
    rows = (np.arange(h * k) + 0.5) / (h * k)
    cols = (np.arange(w * k) + 0.5) / (w * k)
    elev = (0.5 - rows) * np.pi
    lon = (0.5 - cols) * 2.0 * np.pi
    el, lo = np.meshgrid(elev, lon, indexing="ij")
    d = np.stack([np.cos(el) * np.cos(lo), np.cos(el) * np.sin(lo), np.sin(el)], axis=-1)
    f = np.maximum(d, 0.0) * np.cos(el)[..., None]
    wt = np.cos(el)[..., None]
    want = f.reshape(h, k, w, k, 3).sum(axis=(1, 3)) / wt.reshape(h, k, w, k, 1).sum(axis=(1, 3))
    np.testing.assert_allclose(m, want, atol=DIRECTION_ATOL)
    # The orientation itself: +X at the centre, +Y a quarter from the left, +Z at the top.
    assert np.argmax(m[h // 2, :, 0]) in (w // 2 - 1, w // 2)
    assert np.argmax(m[h // 2, :, 1]) in (w // 4 - 1, w // 4)
    assert np.all(m[0, :, 2] > 0.95)


def test_the_map_reduces_by_solid_angle():
    px = np.zeros((8, 16, 3))
    px[0] = 1.0                                  # the row at the zenith, the smallest texels
    got = world_map.downsample(px, width=4)
    el = (0.5 - (np.arange(8) + 0.5) / 8) * np.pi
    want = np.cos(el[0]) / np.cos(el[:4]).sum()
    np.testing.assert_allclose(got[0], want)
    np.testing.assert_allclose(got[1], 0.0)
    with pytest.raises(ValueError, match="does not reduce"):
        world_map.downsample(np.zeros((8, 12, 3)), width=8)


def test_a_sun_disc_is_found_with_its_power_and_taken_out_of_the_map():
    """A synthetic panorama: a uniform sky of 1 and a 3-pixel disc of 1e6 at a known direction.
    The disc carries its power above the sky; the map keeps the sky."""
    h, w = 64, 128
    px = np.ones((h, w, 3))
    d, omega = world_map.pixel_directions(h, w)
    # The solid angles tile the sphere.
    assert omega.sum() == pytest.approx(4 * np.pi, rel=1e-12)
    disc = [(20, 40), (20, 41), (21, 40)]
    for r, c in disc:
        px[r, c] = [1e6, 0.9e6, 0.8e6]
    out, found = world_map.split_sun(px)
    np.testing.assert_allclose(out, 1.0)
    power = sum((np.array([1e6, 0.9e6, 0.8e6]) - 1.0) * omega[r, c] for r, c in disc)
    np.testing.assert_allclose(found["power"], power, rtol=1e-12)
    towards = sum(d[r, c] * omega[r, c] for r, c in disc)
    towards /= np.linalg.norm(towards)
    # Weighted by the excess luminance, not the solid angle: within a pixel (2.8 degrees).
    assert np.dot(found["towards"], towards) > np.cos(np.radians(2.8))
    # A clear sky's bright circumsolar glow alone (100x its ring) is no sun.
    glow = np.ones((h, w, 3))
    glow[20, 40] = 100.0
    assert world_map.split_sun(glow)[1] is None


def _sky_world(elevation, rotation):
    world, nt = _world("Sky")
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sun_disc = True
    sky.sun_elevation, sky.sun_rotation = elevation, rotation
    nt.links.new(sky.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    return world


def test_blenders_sky_texture_gives_its_sun_where_the_node_puts_it():
    """Blender's own sky model (Nishita in 4.x, multiple scattering in 5.0): the sun found is at
    the node's elevation, a node turned by 90 degrees turns it by 90 degrees, and without it the
    map is a sky (its brightest texel within 1000x its median)."""
    suns = []
    for rotation in (0.0, np.pi / 2):
        world = _sky_world(np.radians(30.0), rotation)
        m, sun = world_map.world_map(world)
        assert sun is not None and sun["name"] == f"World '{world.name}' sun"
        towards = -np.array(sun["direction"])
        # Measured in its window (pixels of ~0.03 degrees): the node's elevation within 0.1
        # degrees, and a disc of about the node's size (pixels above half its peak).
        assert np.degrees(np.arcsin(towards[2])) == pytest.approx(30.0, abs=0.1)
        assert sun["angle"] == pytest.approx(bpy.data.worlds[world.name].node_tree.nodes[
            "Sky Texture"].sun_size, rel=0.25)
        lum = m @ [0.2126, 0.7152, 0.0722]
        assert lum.max() < 1000 * np.median(lum[lum > 0])
        suns.append(towards)
    flat = [np.arctan2(t[1], t[0]) for t in suns]
    turn = np.degrees((flat[1] - flat[0] + np.pi) % (2 * np.pi) - np.pi)
    assert abs(turn) == pytest.approx(90.0, abs=2.0)
