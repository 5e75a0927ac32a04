"""Progress reporting and cancellation, shared by every long-running stage."""

import contextlib
import threading
import time

from .constants import POLL_INTERVAL
from .errors import BakeCancelled


class Monitor:
    """Carries a progress callback and a cancel check through a bake.

    Parameters
    ----------
    progress : callable(fraction: float, message: str) or None
        Called with the overall fraction done in [0, 1] and a short message.
    cancel : callable() -> bool or None
        Returning True asks the bake to stop; the next :meth:`update` raises
        :class:`~core.errors.BakeCancelled`.

    Stages call :meth:`update` after every chunk of work; chunks are sized so that this happens at
    least every ``POLL_INTERVAL`` seconds. A stage owns a sub-range of [0, 1] set by :meth:`stage`.
    """

    def __init__(self, progress=None, cancel=None):
        self._progress = progress
        self._cancel = cancel
        self._lo, self._hi = 0.0, 1.0
        self._last_call = 0.0

    def stage(self, lo, hi):
        """Map the fractions of the next updates onto [lo, hi] of the whole bake."""
        self._lo, self._hi = float(lo), float(hi)

    @contextlib.contextmanager
    def part(self, k, n):
        """Within the block, the updates map onto part ``k`` of ``n`` equal parts of the current
        stage (several solves in one stage: core.groups), then onto the whole stage again."""
        lo, hi = self._lo, self._hi
        Monitor.stage(self, lo + (hi - lo) * k / n, lo + (hi - lo) * (k + 1) / n)
        try:
            yield self
        finally:
            Monitor.stage(self, lo, hi)

    def check(self):
        """Raise BakeCancelled if the cancel check says so."""
        if self._cancel is not None and self._cancel():
            raise BakeCancelled("bake cancelled")

    def update(self, fraction, message=""):
        """Report progress within the current stage and honour a pending cancel."""
        self.check()
        if self._progress is not None:
            f = self._lo + (self._hi - self._lo) * min(max(float(fraction), 0.0), 1.0)
            self._progress(f, message)
        self._last_call = time.perf_counter()

    def due(self):
        """True when a poll interval has passed since the last update."""
        return time.perf_counter() - self._last_call >= POLL_INTERVAL


def poll(monitor, message):
    """In a loop of one stage: once a poll interval has passed, honour a pending cancel.

    Reports the start of the current stage (fraction 0), so progress never moves backwards.
    ``monitor`` may be None (nothing to poll).
    """
    if monitor is not None and monitor.due():
        monitor.update(0.0, message)


_running = threading.local()


@contextlib.contextmanager
def watching(cancel):
    """Within the block, :func:`checkpoint` in this thread honours ``cancel`` (the bake's
    cancel check, or None): for work deep in a stage that has no monitor at hand."""
    previous = getattr(_running, "cancel", None)
    _running.cancel = cancel
    try:
        yield
    finally:
        _running.cancel = previous


def checkpoint():
    """Raise BakeCancelled if the bake running in this thread (:func:`watching`) is asked to
    stop; outside a bake, nothing."""
    cancel = getattr(_running, "cancel", None)
    if cancel is not None and cancel():
        raise BakeCancelled("bake cancelled")


#: A monitor that never reports and never cancels.
SILENT = Monitor()


class SubMonitor:
    """A part [lo, hi] of another monitor's current stage, for a stage made of several steps.

    ``update(f)`` reports ``lo + (hi - lo) f`` to the parent, so that two steps of one stage
    (e.g. the element gathers, then the vertex gather) keep the fraction non-decreasing.
    """

    def __init__(self, parent, lo, hi):
        self._parent, self._lo, self._hi = parent, float(lo), float(hi)

    def update(self, fraction, message=""):
        f = min(max(float(fraction), 0.0), 1.0)
        self._parent.update(self._lo + (self._hi - self._lo) * f, message)
