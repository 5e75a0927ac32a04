"""One BLAS thread in the bake's process while the stages that share work with the workers run.

NumPy's OpenBLAS starts a thread per core for a matrix product and keeps those threads spinning
for a while after it. During the form factors and the gathers, the worker processes
(:mod:`core.parallel`) already fill the cores, and every product this process makes there (a
gather batch's rows times the radiance, several per batch) woke threads that took the workers'
cores: the office sample with 2 workers spent 19.0 s of CPU in this process against 10.7 s with
``OPENBLAS_NUM_THREADS=1``, and baked in 61.8 s against 57.1 s (2026-11-29). Those stages run
with one thread whether the bake uses workers or not, so their results are the same with any
number of workers (OpenBLAS's sums depend on its thread count). The solve keeps its threads:
nothing else runs then.

OpenBLAS is found among the libraries the process has loaded (``/proc/self/maps``) or beside
NumPy (its wheels' ``numpy.libs``, ``.libs``, ``.dylibs``), and called through ctypes under the
names its builds export (NumPy 1.x wheels: ``openblas_set_num_threads64_``; 2.x:
``scipy_openblas_set_num_threads64_``; Debian's: ``openblas_set_num_threads``). Another BLAS
(Accelerate, MKL, the reference BLAS) is left as it is: those do not spin, or are not threaded.
"""

import contextlib
import ctypes
import glob
import os
import threading

import numpy as np

_PREFIXES = ("openblas", "scipy_openblas")
_SUFFIXES = ("", "64_")

_lock = threading.Lock()
_found = []             # [(get, set)] once looked for
_looked = [False]
_depth = [0]            # nested one_thread() calls; the outermost restores
_before = []


def _candidates():
    """Paths of loaded or bundled shared libraries whose name says OpenBLAS."""
    paths = []
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            for line in maps:
                fields = line.split()
                path = fields[-1] if len(fields) >= 6 else ""
                if "openblas" in path.lower() and ".so" in path:    # or openblas-*/libblas
                    paths.append(path)
    except OSError:
        pass
    here = os.path.dirname(np.__file__)
    for folder in (os.path.join(here, os.pardir, "numpy.libs"), os.path.join(here, ".libs"),
                   os.path.join(here, ".dylibs")):
        paths += glob.glob(os.path.join(folder, "*openblas*"))
    return list(dict.fromkeys(os.path.realpath(p) for p in paths))


def _controls():
    """[(get, set)] thread-count functions of every OpenBLAS this process can reach."""
    with _lock:
        if not _looked[0]:
            _looked[0] = True
            for path in _candidates():
                try:
                    lib = ctypes.CDLL(path)
                except OSError:
                    continue
                for prefix in _PREFIXES:
                    for suffix in _SUFFIXES:
                        get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                        set_ = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                        if get is not None and set_ is not None:
                            get.restype, set_.argtypes = ctypes.c_int, [ctypes.c_int]
                            _found.append((get, set_))
    return _found


def threads():
    """The thread counts of the OpenBLAS libraries found ([] when none is)."""
    return [get() for get, _ in _controls()]


@contextlib.contextmanager
def one_thread():
    """Run the block with one OpenBLAS thread; the counts before are restored after it."""
    controls = _controls()
    with _lock:
        if _depth[0] == 0:
            _before[:] = [get() for get, _ in controls]
            for _, set_ in controls:
                set_(1)
        _depth[0] += 1
    try:
        yield
    finally:
        with _lock:
            _depth[0] -= 1
            if _depth[0] == 0:
                for (_, set_), n in zip(controls, _before):
                    set_(n)
