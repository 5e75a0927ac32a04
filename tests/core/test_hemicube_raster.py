"""Rasteriser internals of the hemicube (core/hemicube_chunk.py, core/hemicube_raster.py).

How work is cut (blocks of items, of fragments, pyramid culling, buffers kept per thread) must not
change a single bit of the rows; closed boxes keep rows summing to 1 (the furnace identity).
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from builders import box_quads, centred_square as square, quad_patches as make_patches
from core import hemicube, hemicube_chunk, hemicube_raster
from core.hemicube import hemicube_rows


def test_rows_do_not_depend_on_how_fragments_are_blocked(monkeypatch):
    # Spans are drawn in blocks, _FRAG_SLOTS pixels per span at once (slots past a span get
    # a negative key) and the rest of longer spans in a second pass. Blocks of 3 spans put
    # block edges everywhere; the rows must be bit-identical, and closed-box rows still sum
    # to 1 (a padding slot that wrote a pixel, or a lost fragment, would break one of both).
    corners, _ = box_quads((1.0, 1.0, 1.0), 0.25)
    patches = make_patches(corners)
    sources = np.arange(0, corners.shape[0], 7)
    whole = hemicube_rows(patches, sources, resolution=32, rotate=True, rng=2)
    monkeypatch.setattr(hemicube_raster, "_FRAG_BLOCK", 3)
    blocked = hemicube_rows(patches, sources, resolution=32, rotate=True, rng=2)
    assert np.array_equal(whole, blocked)
    assert np.allclose(whole.sum(axis=1), 1.0, atol=1e-12)


def _room_with_furniture():
    """A closed box with a floating slab: general (near-clipped) items and items drawn on
    several faces at once, from every source."""
    corners, _ = box_quads((1.0, 1.5, 1.0), 0.25)
    slab = [square(0.5, 0.75, 0.4, 0.5), square(0.5, 0.75, 0.4, 0.5, facing_up=False)]
    return make_patches(np.concatenate([corners, slab]))


def test_rows_do_not_depend_on_how_items_are_blocked(monkeypatch):
    # Items are set up and drawn _ITEM_BLOCK at a time, and the rest of long spans is held
    # back until _FRAG_BLOCK of them wait; the item ids (and so the tie rule) do not depend on
    # either. Tiny blocks put block edges everywhere, in the main, face and general groups.
    patches = _room_with_furniture()
    sources = np.arange(0, patches.centres.shape[0], 5)
    whole = hemicube_rows(patches, sources, resolution=32, rotate=True, rng=4)
    monkeypatch.setattr(hemicube_raster, "_ITEM_BLOCK", 7)
    monkeypatch.setattr(hemicube_raster, "_FRAG_BLOCK", 5)
    blocked = hemicube_rows(patches, sources, resolution=32, rotate=True, rng=4)
    assert np.array_equal(whole, blocked)
    assert np.allclose(whole.sum(axis=1), 1.0, atol=1e-12)


def test_polygons_beyond_a_face_are_dropped_only_when_clipping_would_drop_them(monkeypatch):
    # Polygons straddling a face's near plane are first tested against the planes through the
    # eye and the face's borders (with a margin) and clipped only if they may reach the face.
    # Without that test (an infinite margin drops nothing) the rows must be the same.
    patches = _room_with_furniture()
    sources = np.arange(patches.centres.shape[0])
    fast = hemicube_rows(patches, sources, resolution=16)
    monkeypatch.setattr(hemicube_chunk, "_PYRAMID_MARGIN", np.inf)
    hemicube._CACHE.clear()
    slow = hemicube_rows(patches, sources, resolution=16)
    assert np.array_equal(fast, slow)


def test_kept_buffers_do_not_leak_between_calls_or_threads():
    # The z-buffer and the tiled delta form factors are kept per thread and reused: calls of
    # other sizes and resolutions in between, or in other threads at the same time, must not
    # change a result.

    patches = _room_with_furniture()
    p = patches.centres.shape[0]
    first = hemicube_rows(patches, np.arange(p), resolution=16)
    hemicube_rows(patches, [0, 1, 2], resolution=32)
    hemicube_rows(patches, np.arange(p // 2), resolution=16)
    assert np.array_equal(hemicube_rows(patches, np.arange(p), resolution=16), first)
    jobs = [(np.arange(p), 16), (np.arange(3), 32), (np.arange(p)[::-1], 16)] * 3
    with ThreadPoolExecutor(max_workers=3) as pool:
        results = list(pool.map(lambda job: hemicube_rows(patches, job[0], resolution=job[1]),
                                jobs))
    for (sources, resolution), rows in zip(jobs, results):
        if resolution == 16:
            assert np.array_equal(rows, first[sources])
