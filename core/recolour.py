"""Relight after a change of the lights' power or colour only: no shadow ray, no gather (issue 12).

A light's direct light is linear in its power, and what its shadow rays find does not depend on
it. When a relight changes only the power or colour of point, spot and sun lights, or the
strength or colour of exactly lit emitters (:mod:`core.emitters`), the bake's
:class:`core.lights.DirectLight` is recoloured (its shadow rays read back from its
:class:`core.shadow_memo.ShadowMemo`), and the direct light kept at every gathered point (receiver
elements, output points) is replaced by the new lights' light at the same points. The gathers'
rows, the receiver elements and the radiosity mesh are kept, as for a change of emission; then the
relight is one solve on the kept form factors.
"""

import dataclasses

import numpy as np

from .adaptive import AdaptiveState
from .emitters import exact_materials
from .pipeline import Gather


def recoloured(state, scene):
    """The bake's direct light lit as ``scene`` (the relight's scene) lights it, reading its
    shadow rays back; None when anything but power or colour changed (cast again)."""
    direct, st = state.direct, state.settings
    if direct is None:
        return None
    chosen = exact_materials(scene, st.exact_direct, st.resolution)
    emitters = None
    if direct.emitters is not None:
        emitters = direct.emitters.recoloured(scene, chosen)
        if emitters is None:
            return None
    elif chosen.any():
        return None
    return direct.recoloured(scene.lights, emitters)


def regathered(gather, old, new):
    """The kept gather (a :class:`core.adaptive.AdaptiveState` or :class:`core.pipeline.Gather`)
    with ``new``'s direct light in place of ``old``'s at its points; None for anything else
    (gathered again)."""
    same = old.recoloured(old.lights, old.emitters)
    elements = getattr(gather, "elements", None)
    if elements is not None and elements.direct is not None:
        elements = elements.with_direct(_moved(elements.direct, *elements.points(), same, new))
    if isinstance(gather, AdaptiveState):
        direct = gather.direct.copy()
        at = np.flatnonzero(gather.cast)
        direct[at] = _moved(direct[at], gather.points[at], gather.normals[at], same, new)
        return AdaptiveState(**{**gather.__dict__, "direct": direct, "elements": elements})
    if isinstance(gather, Gather):
        direct = gather.direct
        if direct is not None:
            direct = _moved(direct, gather.groups.points, gather.groups.normals, same, new)
        return dataclasses.replace(gather, direct=direct, elements=elements)
    return None


def _moved(kept, points, normals, old, new):
    """``kept`` (n, 3), what ``old`` added at the points (its lights' light, and the world's
    share), with ``new``'s lights' light in place of ``old``'s."""
    light = new.incident(points, normals)
    if old.world is None and old.sky is None:
        return light
    return light + np.maximum(kept - old.incident(points, normals), 0.0)
