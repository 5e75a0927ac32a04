"""Several relights of one bake at once: the light groups' own solutions (issue 12).

A relight's solve assembles the kept form factors into the dense matrix of the solved nodes,
scales it reciprocal again and sweeps it (block Gauss-Seidel); on the 12,767-patch generated
office that is 3 s of a 6 s relight, and the matrix is the same for every emission. The light
groups of the add-on need one relight per group (each group's light alone), so
:func:`relight_many` prepares each relight's light as :func:`core.relight` does, then solves them
all on one matrix (:func:`core.pipeline.solve_many`: assembled and balanced once, every emission
swept together, so a sweep reads the matrix once for all), then makes each one's colours.

Each result is what :func:`core.relight` gives for its change, to the solver's tolerance: the
shared sweeps stop when every emission has converged, so each is swept at least as often as it
would be alone.
"""

import time
from collections import namedtuple

import numpy as np

from . import memory, parallel
from .bake import _STAGES, _LevelMonitor, _back, _front, _prepare, _recomputed
from .pipeline import solve_many
from .progress import Monitor, watching

__all__ = ["relight_many"]

_CHANGES = ("reflectance", "emission", "back_emission", "lights")

#: What :func:`core.bake._front` returns, and a relight waiting for its solve.
_Front = namedtuple("_Front", "direct nodes ff sky timings")
_Ready = namedtuple("_Ready", "i state scene t_start monitor front")


def relight_many(result, changes, *, progress=None, cancel=None):
    """``[core.relight(result, **c) for c in changes]``, solved on one matrix.

    Parameters
    ----------
    result : BakeResult
        From :func:`core.bake` or :func:`core.relight`.
    changes : sequence of dict
        Keyword arguments of :func:`core.relight` (``reflectance``, ``emission``,
        ``back_emission``, ``lights``), one dict per relight.
    progress, cancel : callables, optional
        As in :func:`core.bake`; the progress bar is split into one equal part per relight.

    Returns
    -------
    list of BakeResult
        One per change, in order. A change that gives another matrix (new reflectance, nodes
        never reached before, a bake without kept form factors, shadow lines that moved) is
        solved on its own, as :func:`core.relight` solves it; the others share one solve, and
        their reports say so (``shared_solve``: how many, and its seconds).
    """
    changes = list(changes)
    for c in changes:
        wrong = sorted(set(c) - set(_CHANGES))
        if wrong:
            raise TypeError(f"relight_many: unknown change {wrong[0]!r}; expected "
                            f"{', '.join(_CHANGES)}")
    with watching(cancel):
        return _many(result, changes, progress, cancel)


def _many(result, changes, progress, cancel):
    n = len(changes)
    out = [None] * n
    ready = []                               # _Ready
    for i, c in enumerate(changes):
        state, scene, t_start, again = _prepare(result, progress=progress, cancel=cancel,
                                                **{k: c.get(k) for k in _CHANGES})
        if again is not None:
            out[i] = again                   # the shadow lines moved: baked again
            continue
        with parallel.using(state.settings.workers, cancel):
            if state.store is None:          # a matrix-free bake kept no form factors
                out[i] = _recomputed(scene, state, _LevelMonitor(progress, cancel, i, n),
                                     t_start)
                continue
            monitor = _PhaseMonitor(progress, cancel, i, n)
            front = _Front(*_front(scene, state.settings, state.patches, monitor, state))
        ready.append(_Ready(i, state, scene, t_start, monitor, front))
    clusters = []                            # relights that solve one matrix
    for r in ready:
        cl = next((cl for cl in clusters if _same_matrix(cl[0].front, r.front)), None)
        if cl is None:
            clusters.append([r])
        else:
            cl.append(r)
    for c, cl in enumerate(clusters):
        state = cl[0].state
        t0 = time.perf_counter()
        monitor = _PhaseMonitor(progress, cancel, c, len(clusters))
        monitor.stage(*_STAGES["solve"])
        sols = solve_many(cl[0].front.ff, [r.front.nodes for r in cl], state.settings,
                          monitor, state.balance)
        seconds = time.perf_counter() - t0
        memory.mark("solve")
        for r, sol in zip(cl, sols):
            st, f = r.state, r.front
            timings = dict({"patches": 0.0}, **f.timings, solve=seconds / len(cl))
            with parallel.using(st.settings.workers, cancel):
                out[r.i] = _back(r.scene, st.settings, st.patches, r.monitor, r.t_start,
                                 timings, st, st.on_contact, st.contact_lines, (), f.direct,
                                 f.nodes, f.ff, f.sky, sol)
            if len(cl) > 1:
                out[r.i].report["shared_solve"] = dict(relights=len(cl), seconds=seconds)
    return out


class _PhaseMonitor(Monitor):
    """The progress of part ``k`` of ``n`` in each phase of the bake's bar (core.bake._STAGES):
    the fronts (patches and form factors), the solves, the colours. Every relight's front runs
    before the shared solve and every colours after it, so each phase is split into ``n`` equal
    parts and the bar only moves on."""

    PHASES = ((_STAGES["patches"][0], _STAGES["form_factors"][1]), _STAGES["solve"],
              _STAGES["colours"])

    def __init__(self, progress, cancel, k, n):
        super().__init__(progress, cancel)
        self._k, self._n = k, n

    def stage(self, lo, hi):
        p0, p1 = next(p for p in self.PHASES if p[0] <= lo and hi <= p[1])
        at = p0 + self._k * (p1 - p0) / self._n
        super().stage(at + (lo - p0) / self._n, at + (hi - p0) / self._n)


def _same_matrix(a, b):
    """Whether two :func:`core.bake._front` outcomes solve one matrix: the same solved nodes,
    the same stored rows, the same reflectance and nodes allowed (only their light differs)."""
    fa, fb, na, nb = a.ff, b.ff, a.nodes, b.nodes
    return (not fa.overflow and not fb.overflow and np.array_equal(fa.active, fb.active)
            and len(fa.store.batches) == len(fb.store.batches)
            and all(x is y for x, y in zip(fa.store.batches, fb.store.batches))
            and np.array_equal(na.rho, nb.rho) and np.array_equal(na.allowed, nb.allowed)
            and np.array_equal(fa.store.row_sums, fb.store.row_sums, equal_nan=True))
