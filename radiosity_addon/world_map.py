"""A textured world (sky texture, environment image, gradient) as an equirectangular radiance map.

Python cannot evaluate Blender's shader nodes, so the world is *rendered*: Cycles, a panoramic
equirectangular camera at the origin of a temporary scene that holds nothing but the world,
``RENDER_SIZE`` pixels wide, ``RENDER_SAMPLES`` samples a pixel with a box filter (each pixel is
the mean of the world over its own footprint), written to a 32-bit EXR (scene-linear radiance,
no view transform) and read back. The map is then averaged down to ``MAP_SIZE`` x ``MAP_SIZE/2``
texels, each weighted by its solid angle, so that the hemicube's pixels, which sample the map at
their own directions (:class:`core.sky.Environment`), see a band-limited sky: a sun disc in the
world is spread over one texel (about 5.6 degrees) with its power kept.

Pixel (row ``r`` from the top, column ``c``) looks along longitude ``(0.5 - (c + 0.5) / W) 2 pi``
from +X towards +Y and elevation ``(0.5 - (r + 0.5) / H) pi``: the map's centre is +X, a quarter
from the left +Y, the top row the zenith (+Z). Everything made here is removed again, whatever
happens: the temporary scene, camera, image and file, and the Render Result if it did not exist.
"""

import math
import os
import shutil
import tempfile

import bpy
import numpy as np

from ..core.sky import Environment

#: Width of the rendered panorama (pixels; the height is half).
RENDER_SIZE = 256

#: Cycles samples a pixel: the mean of the world over the pixel's footprint (a 0.5 degree sun
#: disc covers a tenth of a pixel, so 64 samples leave its power within a few per cent).
RENDER_SAMPLES = 64

#: Width of the map the bake samples (texels; the height is half): 5.6 degree texels, a few
#: hemicube pixels each at the default resolution.
MAP_SIZE = 64


def render_world(world, size=RENDER_SIZE, samples=RENDER_SAMPLES, window=None):
    """Radiance (rows, columns, 3) float64 of ``world`` per panorama pixel (row 0 the top).

    ``window``: None, the whole sphere in ``size / 2`` x ``size`` pixels; or ``(lon_min,
    lon_max, el_min, el_max)`` (rad, longitude from +X towards +Y), that part in ``size`` x
    ``size`` pixels (:func:`pixel_directions` gives their directions). Raises RuntimeError naming
    the world if the render produces no image."""
    h, w = (size // 2, size) if window is None else (size, size)
    had_result = "Render Result" in bpy.data.images
    tmp_dir = tempfile.mkdtemp(prefix="radiosity-world-")
    scene = cam = obj = img = None
    try:
        scene = bpy.data.scenes.new("Radiosity world map")
        scene.world = world
        cam = bpy.data.cameras.new("Radiosity world map")
        cam.type = "PANO"
        cam.panorama_type = "EQUIRECTANGULAR"
        if window is not None:
            # The camera's longitude runs the other way round (from +X towards -Y).
            cam.longitude_min, cam.longitude_max = -window[1], -window[0]
            cam.latitude_min, cam.latitude_max = window[2], window[3]
        obj = bpy.data.objects.new("Radiosity world map", cam)
        scene.collection.objects.link(obj)
        scene.camera = obj
        # The camera looks along its -Z with +Y up; this turn puts the panorama's centre on
        # world +X and its top row at world +Z (checked by tests/addon/test_world_map.py).
        obj.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
        r = scene.render
        r.engine = "CYCLES"
        r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
        r.use_compositing = False
        r.use_sequencer = False
        r.film_transparent = False
        scene.cycles.samples = samples
        scene.cycles.device = "CPU"
        scene.cycles.pixel_filter_type = "BOX"
        scene.cycles.filter_width = 1.0
        scene.cycles.use_denoising = False
        if hasattr(scene.cycles, "use_adaptive_sampling"):
            scene.cycles.use_adaptive_sampling = False
        r.image_settings.file_format = "OPEN_EXR"
        r.image_settings.color_depth = "32"
        path = os.path.join(tmp_dir, "world.exr")
        r.filepath = path
        bpy.ops.render.render(write_still=True, scene=scene.name)
        if not os.path.exists(path):
            raise RuntimeError(f"World '{world.name}': rendering it to a map made no image")
        img = bpy.data.images.load(path)
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
        return px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    finally:
        for block, coll in ((img, bpy.data.images), (obj, bpy.data.objects),
                            (cam, bpy.data.cameras), (scene, bpy.data.scenes)):
            if block is not None:
                coll.remove(block)
        if not had_result and "Render Result" in bpy.data.images:
            bpy.data.images.remove(bpy.data.images["Render Result"])
        shutil.rmtree(tmp_dir, ignore_errors=True)


def downsample(pixels, width=MAP_SIZE):
    """(width / 2, width, 3): ``pixels`` (H, W, 3) averaged over blocks of W / width pixels,
    each weighted by its solid angle (cos elevation)."""
    h, w = pixels.shape[:2]
    k = w // width
    if k < 1 or w % width or h % (width // 2) or h // (width // 2) != k:
        raise ValueError(f"a {w} x {h} panorama does not reduce to {width} x {width // 2}")
    elev = (0.5 - (np.arange(h) + 0.5) / h) * np.pi
    wt = np.cos(elev)[:, None, None] * np.ones((1, w, 1))
    blocks = (pixels * wt).reshape(width // 2, k, width, k, 3).sum(axis=(1, 3))
    weights = wt.reshape(width // 2, k, width, k, 1).sum(axis=(1, 3))
    return blocks / weights


#: A pixel brighter than this many times the median of the ring around the brightest one is
#: part of a sun disc (a clear sky's brightest part is ~10x its median; Blender's sun disc is
#: ~1e6x).
SUN_CONTRAST = 1000.0

#: Radius of the cone around the brightest pixel searched for the disc, and outer radius of the
#: ring whose radiance replaces it (rad): 5 and 10 degrees.
SUN_CONE = np.radians(5.0)
SUN_RING = np.radians(10.0)

#: The disc is measured again in a window around it, ``SUN_WINDOW`` pixels square and at least
#: ``SUN_MARGIN`` wider than the disc found in the panorama on every side: a 0.5 degree disc
#: covers a tenth of a panorama pixel, whose 64 samples then miss up to 17 % of its power
#: (measured on Blender's sky texture: 130 W/m^2 against 157 at 2048 px).
SUN_WINDOW = 128
SUN_MARGIN = np.radians(1.5)

#: Rec. 709 luminance weights (as core.lux).
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def pixel_directions(h, w, window=None):
    """(h, w, 3) unit directions and (h, w) solid angles of a panorama's pixels (the whole
    sphere, or ``window`` as in :func:`render_world`)."""
    lon0, lon1, el0, el1 = (-np.pi, np.pi, -np.pi / 2, np.pi / 2) if window is None else window
    lat_edges = el1 - (el1 - el0) * np.arange(h + 1) / h               # top row first
    elev = 0.5 * (lat_edges[:-1] + lat_edges[1:])
    lon = lon1 - (lon1 - lon0) * (np.arange(w) + 0.5) / w              # left column: largest
    el, lo = np.meshgrid(elev, lon, indexing="ij")
    d = np.stack([np.cos(el) * np.cos(lo), np.cos(el) * np.sin(lo), np.sin(el)], axis=-1)
    band = np.sin(lat_edges[:-1]) - np.sin(lat_edges[1:])
    return d, np.repeat(band[:, None] * (lon1 - lon0) / w, w, axis=1)


def split_sun(pixels):
    """(pixels without the sun, disc or None): a sun disc in a panorama (H, W, 3).

    The disc is the pixels within ``SUN_CONE`` of the brightest one that are ``SUN_CONTRAST``
    times brighter than the median of the ring out to ``SUN_RING``; they take the ring's mean
    radiance. ``disc``: ``towards`` (unit, its luminance-weighted centre), ``radius`` (rad, the
    farthest disc pixel's centre from it), ``floor`` (the ring's median luminance), ``back``
    (the ring's mean radiance, (3,)) and ``power`` (W/m^2 on a surface facing it, (3,), the
    disc's radiance above ``back`` x its pixels' solid angles)."""
    h, w = pixels.shape[:2]
    d, omega = pixel_directions(h, w)
    lum = pixels @ _LUMA
    peak = np.unravel_index(np.argmax(lum), lum.shape)
    cos = d @ d[peak]
    cone = cos > np.cos(SUN_CONE)
    ring = ~cone & (cos > np.cos(SUN_RING))
    floor = float(np.median(lum[ring])) if ring.any() else 0.0
    disc = cone & (lum > SUN_CONTRAST * max(floor, 1e-30))
    if not disc.any() or lum[peak] <= 0:
        return pixels, None
    back = np.average(pixels[ring], axis=0, weights=omega[ring])
    excess = np.maximum(pixels[disc] - back, 0.0) * omega[disc][:, None]      # W/m^2 each
    towards = (d[disc] * (excess @ _LUMA)[:, None]).sum(axis=0)
    towards /= np.linalg.norm(towards)
    out = pixels.copy()
    out[disc] = back
    radius = float(np.arccos(np.clip(d[disc] @ towards, -1.0, 1.0)).max())
    return out, dict(towards=towards, radius=radius, floor=floor, back=back,
                     power=excess.sum(axis=0))


def measure_sun(world, disc, size=SUN_WINDOW, samples=RENDER_SAMPLES):
    """The sun light (a dict for core.light_list.make_lights) of ``disc`` (:func:`split_sun`),
    measured in a window rendered around it: ``strength`` x ``color`` the power above the
    ring's radiance, ``direction`` the way its light travels, ``angle`` the diameter of a disc
    of the solid angle its pixels above half the peak cover."""
    t = disc["towards"]
    el = float(np.arcsin(np.clip(t[2], -1.0, 1.0)))
    half = disc["radius"] + SUN_MARGIN
    if abs(el) + half >= np.pi / 2 - 1e-6:        # near the zenith or the nadir: whole sky
        return _sun(world, disc["power"], t, 2.0 * disc["radius"])
    lon = float(np.arctan2(t[1], t[0]))
    wide = half / np.cos(abs(el) + half)
    window = (lon - wide, lon + wide, el - half, el + half)
    px = render_world(world, size, samples, window)
    d, omega = pixel_directions(size, size, window)
    lum = px @ _LUMA
    inside = lum > SUN_CONTRAST * max(disc["floor"], 1e-30)
    if not inside.any():
        return _sun(world, disc["power"], t, 2.0 * disc["radius"])
    excess = np.maximum(px[inside] - disc["back"], 0.0) * omega[inside][:, None]
    towards = (d[inside] * (excess @ _LUMA)[:, None]).sum(axis=0)
    core = lum > 0.5 * lum.max()
    angle = 2.0 * np.sqrt(omega[core].sum() / np.pi)
    return _sun(world, excess.sum(axis=0), towards / np.linalg.norm(towards), angle)


def _sun(world, power, towards, angle):
    top = float(power.max())
    return dict(kind="sun", name=f"World '{world.name}' sun", direction=tuple(-towards),
                strength=top, color=tuple(power / max(top, 1e-300)), angle=float(angle))


def world_map(world):
    """(map, sun): the (MAP_SIZE / 2, MAP_SIZE, 3) radiance map of ``world`` for
    :class:`core.sky.Environment`, and the sun found in it (:func:`split_sun`,
    :func:`measure_sun`) or None."""
    pixels, disc = split_sun(render_world(world))
    sun = None if disc is None else measure_sun(world, disc)
    return downsample(pixels), sun


def read_world(scene):
    """(world, sun, note) of the scene's world, each None when there is none.

    A uniform world (no node tree, or a Background node whose Color and Strength are not linked)
    is its radiance (3,): colour x strength, what Cycles' diffuse rays see where they hit
    nothing. Any other world (a sky texture, an environment image, a gradient, another shader)
    is rendered (:func:`world_map`) into a :class:`core.sky.Environment`, and a sun disc in it
    becomes a sun light (a dict for core.light_list.make_lights); ``note`` says so. A world
    whose Diffuse ray visibility is off lights nothing, as in Cycles.
    """
    world = scene.world
    if world is None or world.cycles_visibility.diffuse is False:
        return None, None, None
    colour, strength = np.array(world.color[:3], dtype=np.float64), 1.0
    tree = world.node_tree
    if bpy.app.version < (5, 0, 0) and not world.use_nodes:  # always on (deprecated) in 5
        tree = None
    if tree is not None:
        outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
        surface = outs[0].inputs.get("Surface") if outs else None
        if surface is None or not surface.is_linked:
            return None, None, None
        node = surface.links[0].from_node
        plain = node.bl_idname == "ShaderNodeBackground" and not (
            node.inputs["Color"].is_linked or node.inputs["Strength"].is_linked)
        if not plain:
            # The render needs the world itself, not the depsgraph's evaluated copy of it.
            texels, sun = world_map(world.original)
            if not np.any(texels > 0) and sun is None:
                return None, None, None
            note = (f"World '{world.name}' ({node.name}) is lit from a {texels.shape[1]} x "
                    f"{texels.shape[0]} map rendered by Cycles")
            if sun is not None:
                note += (f"; its sun disc became a sun light of {sun['strength']:.4g} W/m^2 "
                         f"at {np.degrees(np.arcsin(-sun['direction'][2])):.1f} degrees")
            return Environment(texels), sun, note
        colour = np.array(node.inputs["Color"].default_value[:3], dtype=np.float64)
        strength = float(node.inputs["Strength"].default_value)
    radiance = np.maximum(colour * strength, 0.0)
    if not np.any(radiance > 0):
        return None, None, None
    return radiance, None, None
