"""The bake's hemicube calls on a Dask distributed cluster (issue 13: the same chunks on an
existing distributed engine).

:func:`core.parallel.set_backend` hands every call a bake shares (the patches' form-factor
rows, the element and vertex gathers) to a backend instead of this machine's worker processes.
:class:`DaskBackend` is one: each call is cut into one contiguous part per worker thread of the
cluster, each part runs :func:`core.parallel.compute_part` on a Dask worker (the same code a
local worker runs), and the parts go back in order, so the result is bit-identical to one
process. The polygons of a set of patches are scattered to the workers once.

The workers import the repository as the top-level package ``core``: :func:`connect` puts its
folder on every worker's ``sys.path`` (a farm keeps the repository on shared storage, or
installs it on every node). The task is submitted as ``core.parallel.compute_part`` by that
name, never as the extension's own module (``bl_ext.…``), which a worker cannot import.

This module imports nothing from Blender or from the add-on package (the tests load it from its
file) and needs ``distributed`` only when used.
"""

import collections
import importlib
import itertools
import os
import sys
import time

#: Seconds between two looks at the cancel check while the cluster computes.
WAIT_STEP = 0.05

#: The folder that holds ``core/``.
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


_ADD_PATH = "import sys\nif root not in sys.path:\n    sys.path.insert(0, root)\n"

#: Run on every worker too: Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, and
#: glibc then maps every array above 128 kB afresh and unmaps it when freed (setting one of these
#: thresholds turns off glibc's adaptive one), so each hemicube chunk's temporaries page-fault
#: anew: measured 26.1 CPU s in the workers against 10.1 s with this (2 rooms, 5,000 vertices,
#: 2026-11-27). Thresholds of 1 GiB bring back the local pool's behaviour. Not glibc: no-op.
_MALLOC_TUNE = """
try:
    import ctypes, sys
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 1 << 30)       # M_MMAP_THRESHOLD
        libc.mallopt(-1, 1 << 30)       # M_TRIM_THRESHOLD
except (OSError, AttributeError):
    pass
"""


def _add_path(root):
    """Run on every worker: the repository's ``core`` importable by that name."""
    if root not in sys.path:
        sys.path.insert(0, root)
    return root


def _top_level_parallel():
    """``core.parallel`` imported by its top-level name (the name workers resolve the task
    by), whatever package this process imported the add-on under."""
    _add_path(ROOT)
    return importlib.import_module("core.parallel")


class DaskBackend:
    """A Dask ``distributed.Client``'s cluster as a :mod:`core.parallel` backend.

    Parameters
    ----------
    client : distributed.Client
    parallel : module
        The bake's own ``core.parallel`` (inside Blender, the extension's): its
        :class:`WorkerError` and ``BakeCancelled`` are the errors the bake handles.
    """

    name = "dask"

    def __init__(self, client, parallel):
        self.client, self.parallel = client, parallel
        self.size = max(1, sum(client.nthreads().values()))
        self.pending = collections.OrderedDict()         # job id -> its futures, oldest first
        self.cpu_seconds = 0.0
        self.peak_mb = None
        self._task = _top_level_parallel().compute_part
        self._scattered = collections.OrderedDict()      # geometry id -> (geometry, future)
        self._ids = itertools.count(1)

    def alive(self):
        return self.client.status == "running"

    def close(self):
        """Cancel what is still running (the client stays connected)."""
        for futures in self.pending.values():
            self.client.cancel(futures)
        self.pending.clear()

    def _geometry(self, sc):
        key = id(sc.geometry)
        kept = self._scattered.get(key)
        if kept is None or kept[0] is not sc.geometry:
            geometry, _ = self.parallel.part_message(sc)
            # In a list: a dict given to scatter would be scattered by its keys, as Dask keys
            # ('plane_c', ...) that the next geometry would overwrite.
            future = self.client.scatter([geometry], broadcast=True, hash=False)[0]
            kept = self._scattered[key] = (sc.geometry, future)
            while len(self._scattered) > self.parallel.KEPT_GEOMETRIES:
                self._scattered.popitem(last=False)
        return kept[1]

    def submit(self, sc, eyes, frames, parts):
        import numpy as np

        geometry = self._geometry(sc)
        _, scalars = self.parallel.part_message(sc)
        bounds = np.linspace(0, eyes.shape[0], parts + 1).round().astype(np.int64)
        try:
            futures = [self.client.submit(self._task, geometry, scalars,
                                          eyes[bounds[k]:bounds[k + 1]],
                                          frames[bounds[k]:bounds[k + 1]], pure=False)
                       for k in range(parts)]
        except Exception as exc:                  # noqa: BLE001 - the bake falls back
            raise self.parallel.WorkerError(f"the Dask cluster refused the work: {exc}") from exc
        ident = next(self._ids)
        self.pending[ident] = futures
        return ident, bounds

    def collect(self, job, out, cancel, sky_out=None):
        from distributed import wait

        ident, bounds = job
        if not self.pending or next(iter(self.pending)) != ident:
            raise RuntimeError("jobs must be collected in the order they were submitted")
        futures = self.pending.pop(ident)
        try:
            for k, future in enumerate(futures):
                while not future.done():
                    if cancel is not None and cancel():
                        self.client.cancel(futures)
                        raise self.parallel.BakeCancelled("bake cancelled")
                    try:
                        wait(future, timeout=WAIT_STEP)
                    except TimeoutError:      # distributed's is the builtin since 2023
                        pass
                rows, sky, peak, cpu = future.result()
                out[bounds[k]:bounds[k + 1]] = rows
                if sky_out is not None:
                    sky_out[bounds[k]:bounds[k + 1]] = sky
                self.cpu_seconds += cpu
                if peak is not None:
                    self.peak_mb = max(self.peak_mb or 0.0, peak)
        except self.parallel.BakeCancelled:
            raise
        except Exception as exc:                  # noqa: BLE001 - the bake falls back
            self.client.cancel(futures)
            raise self.parallel.WorkerError(f"a Dask task failed: {exc}") from exc
        return out


def connect(address=None, workers=2, wait=30.0):
    """A ``distributed.Client`` whose every worker can import ``core``.

    ``address``: a scheduler's address (``tcp://host:8786``), or the path of a scheduler file
    (``dask scheduler --scheduler-file F``; on shared storage, waited for up to ``wait``
    seconds), or None for a new LocalCluster of ``workers`` single-threaded processes. Waits
    up to ``wait`` seconds for a first worker. Raises ``ClusterError`` with the reason."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ClusterError("Dask distributed is not installed in Blender's Python: "
                           "python -m pip install 'distributed==2026.8.0'") from None
    try:
        if not address:
            client = Client(LocalCluster(n_workers=workers, threads_per_worker=1,
                                         processes=True, dashboard_address=None))
        elif "://" in address or not address.endswith(".json"):
            client = Client(address, timeout=wait)
        else:
            deadline = time.monotonic() + wait
            while not os.path.exists(address) and time.monotonic() < deadline:
                time.sleep(0.5)
            if not os.path.exists(address):
                raise ClusterError(f"no scheduler file at {address} after {wait:g} s")
            client = Client(scheduler_file=address, timeout=wait)
        client.wait_for_workers(1, timeout=wait)
    except ClusterError:
        raise
    except Exception as exc:                       # noqa: BLE001 - one line for the user
        raise ClusterError(f"cannot use the Dask scheduler {address or '(local)'}: "
                           f"{str(exc).strip().splitlines()[-1] if str(exc) else exc!r}") from None
    # By the builtin exec, not by _add_path: Dask sends a function of this module by its name,
    # which inside Blender is the extension's package (bl_ext...), unknown to the workers.
    client.run(exec, _ADD_PATH + _MALLOC_TUNE, {"root": ROOT})
    return client


class ClusterError(RuntimeError):
    """The cluster cannot be reached or used (the message says why)."""


def use(client, parallel):
    """Make ``parallel`` (the bake's ``core.parallel``) share its calls with ``client``'s
    cluster; the backend it used before is returned (give it back with
    ``parallel.set_backend``)."""
    return parallel.set_backend(DaskBackend(client, parallel))
