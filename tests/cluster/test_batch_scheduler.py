"""The headless batch with ``--scheduler``: the bake's hemicube calls on a Dask cluster
(docs/farm.md). ``--scheduler local`` starts a LocalCluster of ``--workers`` processes, as CI
can; a farm gives a scheduler's address or file.

Oracle: the same batch with ``--workers 1`` (this process only): the baked colours must be the
same bits. A scheduler that cannot be reached stops the batch before the bake, saying why.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("distributed")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BATCH = os.path.join(ROOT, "radiosity_addon", "batch.py")
SAMPLE = os.path.join(ROOT, "sample_blends", "cornell_box.blend")

#: Reads every mesh's "Radiosity" colours from a .blend into an .npz (a separate process: the
#: test's own process may hold another Blender file).
READ = """
import sys, bpy, numpy as np
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
out = {}
for obj in bpy.data.objects:
    if obj.type == 'MESH' and 'Radiosity' in obj.data.color_attributes:
        a = obj.data.color_attributes['Radiosity']
        buf = np.empty(len(a.data) * 4, np.float32)
        a.data.foreach_get('color', buf)
        out[obj.name] = buf
np.savez(sys.argv[2], **out)
"""


def _batch(*args):
    return subprocess.run([sys.executable, BATCH, SAMPLE, *args], capture_output=True,
                          text=True, timeout=1200)


def _colours(blend, tmp_path):
    out = str(tmp_path / (os.path.basename(blend) + ".npz"))
    subprocess.run([sys.executable, "-c", READ, blend, out], check=True, capture_output=True,
                   timeout=300)
    with np.load(out) as data:
        return {k: data[k] for k in data.files}


def test_the_batch_on_a_local_dask_cluster_gives_the_bits_of_one_process(tmp_path):
    one, dask = str(tmp_path / "one.blend"), str(tmp_path / "dask.blend")
    a = _batch("--output", one, "--report", str(tmp_path / "one.json"), "--workers", "1")
    assert a.returncode == 0, a.stderr[-3000:]
    b = _batch("--output", dask, "--report", str(tmp_path / "dask.json"),
               "--scheduler", "local", "--workers", "2")
    assert b.returncode == 0, b.stderr[-3000:]
    with open(tmp_path / "dask.json") as fh:
        workers = json.load(fh)["workers"]
    assert workers["backend"] == "dask" and workers["processes"] == 2
    assert workers["shared_calls"] > 0 and "problem" not in workers
    ca, cb = _colours(one, tmp_path), _colours(dask, tmp_path)
    assert ca.keys() == cb.keys() and len(ca) >= 5
    for name in ca:
        assert np.array_equal(ca[name], cb[name]), name


def test_a_scheduler_that_cannot_be_reached_stops_before_the_bake(tmp_path):
    out = tmp_path / "never.blend"
    r = _batch("--output", str(out), "--scheduler", "tcp://127.0.0.1:9",
               "--scheduler-wait", "2")
    assert r.returncode != 0
    assert "cannot use the Dask scheduler tcp://127.0.0.1:9" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()
