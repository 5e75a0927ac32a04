"""A false-colour legend composed into an image with NumPy: colour bar, tick marks, labels.

Used where no text drawing is at hand (a headless render, ``--render-lux``): the legend is a panel
added to the right of the image, the ramp of a :class:`core.falsecolour.Scale` as a vertical bar
(bottom: the scale's bottom, top: its top), a white tick mark at every tick and its value beside
it, ``lx`` above. Text uses a built-in 5 x 7 pixel font, scaled by whole pixels (crisp at any
size). Images are rows top-down: ``(H, W, 3)`` float sRGB in [0, 1].
"""

from dataclasses import dataclass

import numpy as np

from .falsecolour import ramp

#: 5 x 7 glyphs ('#' on), the characters a legend needs.
GLYPHS = {
    "0": (" ### ", "#   #", "#  ##", "# # #", "##  #", "#   #", " ### "),
    "1": ("  #  ", " ##  ", "  #  ", "  #  ", "  #  ", "  #  ", " ### "),
    "2": (" ### ", "#   #", "    #", "   # ", "  #  ", " #   ", "#####"),
    "3": ("#####", "   # ", "  #  ", "   # ", "    #", "#   #", " ### "),
    "4": ("   # ", "  ## ", " # # ", "#  # ", "#####", "   # ", "   # "),
    "5": ("#####", "#    ", "#### ", "    #", "    #", "#   #", " ### "),
    "6": ("  ## ", " #   ", "#    ", "#### ", "#   #", "#   #", " ### "),
    "7": ("#####", "    #", "   # ", "  #  ", " #   ", " #   ", " #   "),
    "8": (" ### ", "#   #", "#   #", " ### ", "#   #", "#   #", " ### "),
    "9": (" ### ", "#   #", "#   #", " ####", "    #", "   # ", " ##  "),
    ".": ("     ", "     ", "     ", "     ", "     ", " ##  ", " ##  "),
    "-": ("     ", "     ", "     ", "#####", "     ", "     ", "     "),
    "l": (" ##  ", "  #  ", "  #  ", "  #  ", "  #  ", "  #  ", " ### "),
    "x": ("     ", "     ", "#   #", " # # ", "  #  ", " # # ", "#   #"),
    " ": ("     ",) * 7,
}
GLYPH_W, GLYPH_H = 5, 7

#: Tick mark length and the gap between it and its label, in font pixels.
TICK, GAP = 2, 4

#: Colours of the legend panel (sRGB).
BACKGROUND = (0.13, 0.13, 0.13)
INK = (1.0, 1.0, 1.0)

_MASKS = {c: np.array([[ch == "#" for ch in row] for row in rows]) for c, rows in GLYPHS.items()}


def text_mask(text, size=1):
    """(7 size, (6 n - 1) size) bool pixels of *text* (n characters), one blank column between
    glyphs. Raises ValueError for a character the font lacks."""
    missing = sorted(set(text) - set(GLYPHS))
    if missing:
        raise ValueError(f"text has characters the legend font lacks: {missing}; "
                         f"it has {''.join(sorted(GLYPHS))!r}")
    if not isinstance(size, (int, np.integer)) or size < 1:
        raise ValueError(f"size must be an integer >= 1; got {size!r}")
    if not text:
        return np.zeros((GLYPH_H * size, 0), dtype=bool)
    gap = np.zeros((GLYPH_H, 1), dtype=bool)
    parts = []
    for ch in text:
        parts += [_MASKS[ch], gap]
    mask = np.concatenate(parts[:-1], axis=1)
    return np.repeat(np.repeat(mask, size, axis=0), size, axis=1)


@dataclass(frozen=True)
class Layout:
    """Where the legend's parts are, in the composed image's pixels (rows top-down).

    Attributes
    ----------
    x0 : int
        First column of the legend panel (the input image's width).
    bar : (int, int, int, int)
        The colour bar's columns ``[left, right)`` and rows ``[top, bottom]`` (both inclusive):
        row ``top`` has the ramp's top colour, row ``bottom`` its bottom colour.
    tick_rows : tuple of int
        Row of every tick.
    size : int
        Font pixel size.
    text_x : int
        First column of the labels (a tick mark runs from the bar towards them, with a gap wider
        than a glyph's stroke so that it does not read as a minus sign).
    """

    x0: int
    bar: tuple
    tick_rows: tuple
    size: int
    text_x: int


def layout(height, width, scale):
    """The :class:`Layout` of the legend for an image ``height`` x ``width`` and *scale*."""
    if height < 8 * GLYPH_H:
        raise ValueError(f"the image must be at least {8 * GLYPH_H} pixels high for a legend; "
                         f"got {height}")
    size = max(1, height // 256)
    pad = 4 * size
    bar_left = width + pad
    bar_right = bar_left + 5 * size
    top = pad + GLYPH_H * size * 2 + pad          # room for 'lx' and half a label above
    bottom = height - 1 - pad - (GLYPH_H * size) // 2 - pad
    t = scale.position(np.asarray(scale.ticks, dtype=np.float64))
    rows = tuple(int(r) for r in np.rint(bottom - t * (bottom - top)))
    text_x = bar_right + TICK * size + GAP * size
    return Layout(width, (bar_left, bar_right, top, bottom), rows, size, text_x)


def compose(image, scale):
    """*image* with the legend of *scale* added as a panel on its right.

    Parameters
    ----------
    image : (H, W, 3) array_like of float
        sRGB in [0, 1], rows top-down (H >= 56).
    scale : core.falsecolour.Scale

    Returns
    -------
    (H, W + L, 3) float64 and the :class:`Layout` of the legend.
    """
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image must have shape (H, W, 3); got {image.shape}")
    h, w = image.shape[:2]
    lay = layout(h, w, scale)
    size = lay.size
    left, right, top, bottom = lay.bar
    labels = scale.labels()
    tick_len, text_x = TICK * size, lay.text_x
    chars = max(len(s) for s in labels + ("lx",))
    panel = text_x + chars * (GLYPH_W + 1) * size + 4 * size - w
    out = np.empty((h, w + panel, 3))
    out[:, :w] = image
    out[:, w:] = BACKGROUND
    rows = np.arange(top, bottom + 1)
    t = (bottom - rows) / float(bottom - top)
    out[top:bottom + 1, left:right] = ramp(t)[:, None, :]      # row t: lux at ramp position t
    for row, text in zip(lay.tick_rows, labels):
        out[row:row + size, right:right + tick_len] = INK
        _stamp(out, text, text_x, row - (GLYPH_H * size) // 2, size)
    _stamp(out, "lx", left, top - GLYPH_H * size - GLYPH_H * size // 2 - size, size)
    return out, lay


def _stamp(out, text, x, y, size):
    """Draw *text* in :data:`INK` with its top-left pixel at (row y, column x), clipped."""
    mask = text_mask(text, size)
    h, w = out.shape[:2]
    y0, x0 = max(y, 0), max(x, 0)
    y1, x1 = min(y + mask.shape[0], h), min(x + mask.shape[1], w)
    if y1 <= y0 or x1 <= x0:
        return
    region = out[y0:y1, x0:x1]
    region[mask[y0 - y:y1 - y, x0 - x:x1 - x]] = INK
