"""Peak memory of a bake's stages, for the report (issue 13: time and peak memory per stage).

On Linux the process's peak resident set (``VmHWM`` in ``/proc/self/status``) is reset at the
start of each stage (writing 5 to ``/proc/self/clear_refs``), so a stage's figure is the peak
reached during that stage: what a bake inside Blender adds to what Blender held before. Where that
reset is not possible the figure is the process's peak since it started (``resource``), and
without ``resource`` (Windows) there is none.
"""

import contextlib
import threading

try:
    import resource
except ImportError:                       # Windows
    resource = None

_local = threading.local()


def peak_mb():
    """The peak resident set in MiB since the last reset (or since the process started); None
    if this platform does not say."""
    try:
        with open("/proc/self/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    if resource is None:
        return None
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1024.0 if not _is_bytes() else kb / 2.0 ** 20


def _is_bytes():
    import sys
    return sys.platform == "darwin"       # macOS reports ru_maxrss in bytes


def reset():
    """Start a new peak (Linux); elsewhere nothing."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


@contextlib.contextmanager
def stages():
    """Collect :func:`mark` figures of this thread's stages into the yielded dict (MiB)."""
    previous = getattr(_local, "peaks", None)
    _local.peaks = peaks = {}
    reset()
    try:
        yield peaks
    finally:
        _local.peaks = previous


def mark(stage):
    """Record the peak since the last mark as ``stage``'s (the larger if it ran before), and
    start the next stage's."""
    peaks = getattr(_local, "peaks", None)
    if peaks is None:
        return
    mb = peak_mb()
    if mb is not None:
        peaks[stage] = round(max(mb, peaks.get(stage, 0.0)), 1)
    reset()
