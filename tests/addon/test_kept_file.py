"""A kept bake on disk (radiosity_addon.kept_file): Relight after reopening the .blend, and the
batch's --save-relight and --relight (issue 12: the kept data "must survive saving and
reopening the .blend, or say why not").

Oracle: the same Relight run in the session that baked, on the kept bake in memory. The file
holds that very bake, so the colours must be the same to float32 (the write); a file that does
not belong to the objects it is read for, or that refers to anything but the add-on's classes
and NumPy's arrays, is refused with a message naming it, before anything is written.
"""

import os
import pickle
import shutil

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import read_colours, relight_labels
from test_batch import FAST, run_batch
from test_relight import bake, room

relight = PACKAGE.radiosity_addon.relight
kept_file = PACKAGE.radiosity_addon.kept_file


def _save(path):
    bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False)


def _reopen(path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    assert relight.kept(bpy.context.scene) is None        # nothing in memory after a load


def _hints():
    """The INFO lines the panel's Relight section draws."""
    return relight_labels(PACKAGE.radiosity_addon.relight_ops, icon="INFO")


def _relit(power):
    bpy.data.objects["Bulb"].data.energy = power
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    return read_colours(bpy.data.objects["Room"].data), read_colours(bpy.data.objects["Lamp"].data)


def test_relight_after_reopening_reads_the_kept_bake_saved_beside_the_file(package, tmp_path):
    room()
    bake(save_relight=True)
    blend = tmp_path / "room.blend"
    _save(blend)
    side = tmp_path / "room.radiosity"
    assert side.is_file(), "Save Relight Data wrote no kept bake beside the .blend"
    size = side.stat().st_size
    assert size > 0.5 * relight.kept(bpy.context.scene).kept_mb * 2 ** 20
    expected = _relit(90.0)                     # in this session, on the bake in memory
    assert _hints() == []                       # kept in memory: the light groups show
    _reopen(blend)
    # Before the first Relight reads it, the panel says a file will be read.
    assert _hints() == ["Relight reads room.radiosity"]
    got = _relit(90.0)                          # after reopening: read back from the file
    assert _hints() == []
    assert relight.kept(bpy.context.scene) is not None
    report = bpy.context.scene.radiosity.last_report
    assert '"relight"' in report
    for g, e in zip(got, expected):
        np.testing.assert_array_equal(g, e)
    _save(blend)                                # relit since: the file beside follows the .blend
    _reopen(blend)
    again = _relit(90.0)
    for g, e in zip(again, expected):
        np.testing.assert_array_equal(g, e)
    assert side.stat().st_size > 0


def test_no_file_is_written_unless_asked_and_saving_unchanged_writes_it_once(package, tmp_path):
    room()
    bake()
    _save(tmp_path / "plain.blend")
    assert not (tmp_path / "plain.radiosity").exists()
    bpy.context.scene.radiosity.save_relight = True
    _save(tmp_path / "plain.blend")
    side = tmp_path / "plain.radiosity"
    first = side.stat().st_mtime_ns
    os.utime(side, ns=(first - 10 ** 9, first - 10 ** 9))
    _save(tmp_path / "plain.blend")              # nothing changed: not written again
    assert side.stat().st_mtime_ns == first - 10 ** 9


def test_a_kept_bake_file_of_another_bake_is_refused_naming_it(package, tmp_path):
    room()
    bake(save_relight=True)
    blend, side = tmp_path / "room.blend", tmp_path / "room.radiosity"
    _save(blend)
    shutil.copy(side, tmp_path / "old.radiosity")
    bpy.data.objects["Bulb"].data.energy = 80.0
    bake(save_relight=True)                     # a new bake: other colours, a new file
    _save(blend)
    shutil.copy(tmp_path / "old.radiosity", side)
    _reopen(blend)
    before = read_colours(bpy.data.objects["Room"].data)
    with pytest.raises(RuntimeError, match=r"room\.radiosity: object '(Room|Lamp)' shows "
                                           r"another bake"):
        bpy.ops.radiosity.relight()
    np.testing.assert_array_equal(read_colours(bpy.data.objects["Room"].data), before)


def test_a_file_that_refers_to_anything_else_is_refused_unread(package, tmp_path):
    room()
    bake(save_relight=True)
    blend, side = tmp_path / "room.blend", tmp_path / "room.radiosity"
    _save(blend)
    with open(side, "rb") as fh:
        header = fh.readline()
    hit = tmp_path / "hit"

    class Evil:
        def __reduce__(self):
            return (os.mkdir, (str(hit),))
    with open(side, "wb") as fh:
        fh.write(header)
        pickle.dump({"Scene": Evil()}, fh)
    _reopen(blend)
    with pytest.raises(RuntimeError, match=r"room\.radiosity: unreadable .*posix\.mkdir"):
        bpy.ops.radiosity.relight()
    assert not hit.exists()
    side.write_bytes(b"not a kept bake\n")
    with pytest.raises(RuntimeError, match=r"room\.radiosity: not a kept bake file"):
        bpy.ops.radiosity.relight()


def test_batch_save_relight_then_relight_equals_the_session_relight(package, tmp_path):
    """The batch bakes and writes the kept bake beside its output; the user changes a light in
    the baked file; ``--relight`` writes what a Relight in the baking session writes."""
    room()
    src = tmp_path / "room.blend"
    bake()                                      # only to give the file its settings
    _save(src)
    baked = tmp_path / "baked.blend"
    proc = run_batch(src, "--output", baked, "--save-relight", *FAST)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "baked.radiosity").is_file()
    bpy.ops.wm.open_mainfile(filepath=str(baked))
    bpy.data.objects["Bulb"].data.energy = 90.0
    _save(baked)                                 # no kept bake in memory: the file stays
    relit = tmp_path / "relit.blend"
    proc = run_batch(baked, "--output", relit, "--relight")
    assert proc.returncode == 0, proc.stderr
    assert "relit the kept bake of" in proc.stdout
    # The oracle: this session reads the same file and relights the same change.
    bpy.ops.wm.open_mainfile(filepath=str(baked))
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    expected = read_colours(bpy.data.objects["Room"].data)
    bpy.ops.wm.open_mainfile(filepath=str(relit))
    np.testing.assert_array_equal(read_colours(bpy.data.objects["Room"].data), expected)
    # ... and it differs from the bake (the light did change).
    bpy.ops.wm.open_mainfile(filepath=str(baked))
    assert not np.allclose(read_colours(bpy.data.objects["Room"].data), expected)


def test_batch_relight_refuses_bake_options_and_a_missing_file(package, tmp_path):
    room()
    src = tmp_path / "room.blend"
    _save(src)
    proc = run_batch(src, "--output", tmp_path / "o.blend", "--relight", "--patch-size", "0.3")
    assert proc.returncode != 0
    assert "--relight re-solves the kept bake, so --patch-size would need a new bake" \
        in proc.stderr
    proc = run_batch(src, "--output", tmp_path / "o.blend", "--relight")
    assert proc.returncode != 0
    assert f"no kept bake file at {tmp_path / 'room.radiosity'}" in proc.stderr
    assert not (tmp_path / "o.blend").exists()
