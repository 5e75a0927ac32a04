"""Exceptions raised by the core.

Every domain error derives from :class:`RadiosityError`, so the Blender layer can catch one type
and turn it into a report. Errors about a bad argument are also ``ValueError``/``TypeError`` so
that ordinary Python code can catch them the usual way.
"""


class RadiosityError(Exception):
    """Base class of every error the core raises on purpose."""


class SceneError(RadiosityError, ValueError):
    """The scene arrays are invalid (shape, range, NaN, no emitter, ...)."""


class SettingsError(RadiosityError, ValueError):
    """A bake setting is out of range or unknown."""


class BakeCancelled(RadiosityError):
    """The cancel check asked the bake to stop; nothing was returned or half written."""
