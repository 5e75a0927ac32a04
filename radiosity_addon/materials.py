"""Blender materials and lights -> diffuse reflectance and emitted radiance (RGB, scene-linear).

Only the diffuse part matters to radiosity. A material's surface shader is followed from its
active Material Output: Principled BSDF (Base Color x (1 - metallic) x (1 - transmission),
Emission Color x Emission Strength), Diffuse BSDF (Color), Emission (Color x Strength), Mix Shader
(blend by an unlinked Fac, else half/half) and Add Shader (sum). A colour driven by an Image Texture
uses the image's mean linear colour; a colour driven by any other node tree uses the socket's own
value, else the material's viewport colour. Every such approximation is reported.
"""

import math

import bpy
import numpy as np

#: Reflectance used for faces without a material (and its documented default).
DEFAULT_REFLECTANCE = 0.8

#: Reflectances are clamped below this: rho = 1 makes a closed scene's system singular, and the
#: core requires rho < 1. 0.99 keeps the solve well conditioned (at most ~100 bounces to converge
#: to 1e-4 relative) and is brighter than any real paint (~0.9).
MAX_REFLECTANCE = 0.99

#: Segments of the polygon that stands in for a disk or ellipse area light (area preserved).
ELLIPSE_SEGMENTS = 16


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def image_mean_colour(image):
    """Mean scene-linear RGB of a Blender image, or None if it has no pixels.

    Parameters
    ----------
    image : bpy.types.Image

    Returns
    -------
    (3,) float64 or None
    """
    w, h = image.size[:]
    channels = image.channels
    if w * h == 0 or channels < 3:
        return None
    buf = np.empty(w * h * channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    rgb = buf.reshape(-1, channels)[:, :3].astype(np.float64)
    if not image.is_float and image.colorspace_settings.name.lower().startswith("srgb"):
        rgb = _srgb_to_linear(rgb)
    return rgb.mean(axis=0)


class MaterialReader:
    """Evaluates materials once each and remembers the notes for the bake report."""

    def __init__(self):
        self.notes = []
        self._cache = {}

    def evaluate(self, material):
        """Reflectance and emission of *material* (None: default grey, no emission).

        Returns
        -------
        reflectance : (3,) float64 in [0, MAX_REFLECTANCE]
        emission : (3,) float64 >= 0, radiance
        """
        key = None if material is None else material.name_full
        if key not in self._cache:
            self._cache[key] = self._evaluate(material)
        return self._cache[key]

    def _note(self, text):
        if text not in self.notes:
            self.notes.append(text)

    def _evaluate(self, material):
        if material is None:
            return np.full(3, DEFAULT_REFLECTANCE), np.zeros(3)
        name = material.name
        rho, le = None, np.zeros(3)
        tree = material.node_tree
        if bpy.app.version < (5, 0, 0) and not material.use_nodes:  # always on (deprecated) in 5
            tree = None
        if tree is not None:
            out = _active_output(tree)
            link = _input_link(out.inputs.get("Surface")) if out is not None else None
            if link is not None:
                rho, le = self._shader(name, link.from_node)
        if rho is None:
            rho = np.array(material.diffuse_color[:3], dtype=np.float64)
            self._note(f"Material '{name}': no supported surface shader; used its viewport colour")
        rho = np.asarray(rho, dtype=np.float64)
        if np.any(rho > MAX_REFLECTANCE):
            self._note(f"Material '{name}': reflectance clamped to {MAX_REFLECTANCE}")
        return np.clip(rho, 0.0, MAX_REFLECTANCE), np.maximum(np.asarray(le, np.float64), 0.0)

    def _shader(self, name, node, depth=0):
        """(reflectance or None, emission) of the shader *node*."""
        if depth > 16:
            return None, np.zeros(3)
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            base = self._colour(name, node, "Base Color")
            metal = self._scalar(name, node, "Metallic", 0.0)
            trans = self._scalar(name, node, "Transmission Weight", None)
            if trans is None:
                trans = self._scalar(name, node, "Transmission", 0.0)
            emit_socket = "Emission Color" if "Emission Color" in node.inputs else "Emission"
            emit = self._colour(name, node, emit_socket) * self._scalar(
                name, node, "Emission Strength", 1.0)
            return base * (1.0 - metal) * (1.0 - trans), emit
        if kind == "ShaderNodeBsdfDiffuse":
            return self._colour(name, node, "Color"), np.zeros(3)
        if kind == "ShaderNodeEmission":
            return np.zeros(3), self._colour(name, node, "Color") * self._scalar(
                name, node, "Strength", 1.0)
        if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
            shaders = [s for s in node.inputs if s.type == "SHADER"]
            parts = []
            for s in shaders:
                link = _input_link(s)
                parts.append(self._shader(name, link.from_node, depth + 1) if link else
                             (np.zeros(3), np.zeros(3)))
            rhos = [np.zeros(3) if r is None else r for r, _ in parts]
            les = [e for _, e in parts]
            if kind == "ShaderNodeAddShader":
                return rhos[0] + rhos[1], les[0] + les[1]
            fac = self._scalar(name, node, "Fac", 0.5)
            return (1 - fac) * rhos[0] + fac * rhos[1], (1 - fac) * les[0] + fac * les[1]
        self._note(f"Material '{name}': shader '{node.name}' ({kind}) is not supported; "
                   "used the viewport colour")
        return None, np.zeros(3)

    def _colour(self, name, node, socket_name):
        socket = node.inputs.get(socket_name)
        if socket is None:
            return np.zeros(3)
        link = _input_link(socket)
        if link is None:
            return np.array(socket.default_value[:3], dtype=np.float64)
        src = link.from_node
        if src.bl_idname == "ShaderNodeTexImage" and src.image is not None:
            mean = image_mean_colour(src.image)
            if mean is not None:
                self._note(f"Material '{name}': {socket_name} is textured; used the mean colour "
                           f"of image '{src.image.name}'")
                return mean
        self._note(f"Material '{name}': {socket_name} is driven by node '{src.name}'; used the "
                   "socket's unlinked value as its average")
        return np.array(socket.default_value[:3], dtype=np.float64)

    def _scalar(self, name, node, socket_name, default):
        socket = node.inputs.get(socket_name)
        if socket is None:
            return default
        if _input_link(socket) is not None:
            self._note(f"Material '{name}': {socket_name} is driven by a node; used its "
                       "unlinked value")
        return float(socket.default_value)


def _active_output(tree):
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for n in outs:
        if n.is_active_output and n.target in ("ALL", "CYCLES"):
            return n
    return outs[0] if outs else None


def _input_link(socket):
    if socket is None or not socket.is_linked:
        return None
    link = socket.links[0]
    return link if link.is_valid and not link.is_muted else None


def area_light_polygon(light):
    """Local-space outline of an area light, wound so its Newell normal is -Z (the lit side).

    Parameters
    ----------
    light : bpy.types.AreaLight

    Returns
    -------
    points : (K, 3) float64
        K = 4 for square/rectangle, ELLIPSE_SEGMENTS for disk/ellipse (radius scaled so that the
        polygon's area equals the ellipse's).
    area : float
        The light's true local area (the ellipse's, not the polygon's).
    """
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
    if light.shape in ("SQUARE", "RECTANGLE"):
        x, y = 0.5 * sx, 0.5 * sy
        pts = np.array([[-x, -y, 0], [-x, y, 0], [x, y, 0], [x, -y, 0]], dtype=np.float64)
        return pts, sx * sy
    n = ELLIPSE_SEGMENTS
    area = math.pi * 0.25 * sx * sy
    # A regular n-gon inscribed in radius r has area n r^2 sin(2 pi / n) / 2.
    k = math.sqrt(math.pi / (0.5 * n * math.sin(2 * math.pi / n)))
    a = -np.linspace(0.0, 2 * math.pi, n, endpoint=False)  # clockwise seen from +Z: normal -Z
    pts = np.stack([0.5 * sx * k * np.cos(a), 0.5 * sy * k * np.sin(a), np.zeros(n)], axis=1)
    return pts, area


#: Cycles' area lights: radiance = power / (pi * area), measured (see tests/addon/test_lights.py
#: and docs/addon.md): a W of power spread over a lambertian emitter of area A m^2 leaves it as
#: P / A W/m^2 of exitance, i.e. radiance P / (pi A).
AREA_LIGHT_RADIANCE_PER_WATT = 1.0 / math.pi


def area_light_radiance(light, world_area):
    """Radiance (3,) of an area light whose emitting polygon has *world_area* (Blender units^2).

    Follows Cycles: colour (x blackbody colour when enabled) x power x 2^exposure / (pi x area);
    a light with ``normalize`` off is not divided by its area.
    """
    colour = np.array(light.color[:3], dtype=np.float64)
    if getattr(light, "use_temperature", False):
        colour = colour * np.array(light.temperature_color[:3], dtype=np.float64)
    power = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
    area = world_area if getattr(light, "normalize", True) else 1.0
    return colour * power * AREA_LIGHT_RADIANCE_PER_WATT / max(area, 1e-30)
