"""Worker processes for the hemicube kernel: every core, results bit-identical to one process.

A bake runs inside :func:`using` (:func:`core.bake.bake` does). Inside it,
:func:`core.hemicube_chunk.rows_in_chunks` hands every call large enough to share to
:func:`share`: the eyes are cut into one contiguous part per worker, each worker computes its
part's rows with the same code, and the parts are put back in order. A row depends only on its
own eye, never on which eyes share a chunk (``tests/core/test_parallel.py`` checks it), so the
result is bit-identical to a bake in one process. The hemicube kernel is where a bake spends its
time: the patches' form-factor rows, the element gathers and the output vertices' gathers.
Shadow rays are shared the same way (:func:`share_rays`, from :mod:`core.raycast`): a ray's
answer depends on that ray alone.

**How workers start.** Each is a Python process started with the interpreter this process runs on
(``sys.executable``: inside Blender, the Python that Blender reports; with the bpy module, the
virtual environment's), which imports this package as the top-level ``core`` from its parent
folder. So a worker never imports bpy and never the extension's package name (``bl_ext.…``),
and nothing re-imports the main script, which is what makes ``multiprocessing``'s spawn fail
under Blender. Messages are pickles over the workers' stdin and stdout; a worker's own prints go
to its stderr. The polygons are sent once per set of patches, the eyes with every call. A set
cut out of another (:meth:`core.hemicube_chunk.Geometry.cut`: a gather batch's far-field mix,
cut out of every patch and element) is sent as the cut, the polygons' numbers, and the worker
cuts its copy of the whole: the same arrays, a seventh of the bytes (one room of
bench.interiors: 159 -> 22 MB a bake; the time did not change measurably).

**Lifetime.** One pool per process, started at the first call worth sharing and kept between
bakes (a start costs about 0.3 s per worker); closed at exit. A cancel kills the workers at once
(the wait polls the cancel check every :data:`WAIT_STEP` seconds) and the next bake starts new
ones. If workers cannot start (no Python interpreter found, an import error), the bake runs in
this process and its report says why.
"""

import atexit
import collections
import contextlib
import itertools
import os
import queue
import sys
import threading
import time
import traceback
import weakref

import numpy as np

from .errors import BakeCancelled
from .memory import peak_mb
from .pipes import WorkerError, _command, _receive, _send, _Worker

#: Seconds between two looks at the cancel check while the workers compute.
WAIT_STEP = 0.05

#: Fewest eyes a worker is given: below this the messages cost more than the hemicubes (one
#: hemicube is about 1 ms at R = 64 over a thousand patches; a message under 1 ms).
MIN_EYES = 8

#: Batches of eyes a caller keeps started and not yet used (core.adaptive's and core.elements'
#: gathers): this process prepares the next while the workers draw, and a worker that finished
#: its part of a batch has the next queued. Two, not one: with one, it waited for the other's.
AHEAD = 2

#: Seconds a starting worker has to import NumPy and this package and say it is ready.
START_TIMEOUT = 60.0

#: Fewest rays worth sharing with the workers (a ray costs about 15 us; sending one 56 bytes).
MIN_RAYS = 4096

#: Ray-casting trees a worker keeps (the scene's, and the exact emitters' or lights' own).
KEPT_TREES = 2

#: Sets of polygons a worker keeps (a bake alternates between a few: the patches, the receiver
#: elements, a gather's far-field mix).
KEPT_GEOMETRIES = 4

_local = threading.local()
_pool_lock = threading.Lock()
_pool = [None]              # the process's Pool, or None
_backend = [None]           # another engine's pool (set_backend), or None
_tokens = weakref.WeakKeyDictionary()
_cuts = weakref.WeakKeyDictionary()   # Geometry -> (the Geometry it was cut from, sel, items)
_tree_tokens = {}          # id -> (weak reference, token): trees compare by value
_next_token = itertools.count(1)


def cpu_count():
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def resolve(workers):
    """Worker processes for the ``workers`` setting: None (auto) is one per core."""
    return cpu_count() if workers is None else int(workers)


@contextlib.contextmanager
def using(workers, cancel=None):
    """Within the block, this thread's hemicube calls are shared among ``workers`` processes
    (None: one per core; 1: none). ``cancel`` is the bake's cancel check. Yields a dict that
    the calls fill: ``processes`` (most workers that computed one call's rows), ``calls``,
    ``cpu_seconds`` (the workers' CPU time on rows), ``peak_mb`` (the largest worker's peak
    resident set) and ``problem`` (why the workers could not be used, or None).

    One bake at a time uses the process's pool: a bake in another thread meanwhile runs in its
    own process only."""
    backend = _backend[0] if workers != 1 else None      # 1: this process only, always
    n = resolve(workers) if backend is None else backend.size
    stats = dict(processes=1, calls=0, problem=None, peak_mb=None, cpu_seconds=0.0)
    if backend is not None:
        stats["backend"] = backend.name
    previous = getattr(_local, "context", None)
    owner = n > 1 and previous is None and _pool_lock.acquire(blocking=False)
    if n > 1 and previous is None and not owner:
        stats["problem"] = "another bake in this process is using the workers"
    _local.context = _Context(n, cancel, stats, backend) if owner else None
    try:
        yield stats
    finally:
        _local.context = previous
        if owner:
            pool = backend if backend is not None else _pool[0]
            if pool is not None and pool.pending:   # left uncollected (an error): unknown state
                pool.close()
                if pool is _pool[0]:
                    _pool[0] = None
            _pool_lock.release()


class _Context:
    """The pool settings of one bake (held by the thread that runs it)."""

    def __init__(self, n, cancel, stats, backend=None):
        self.n, self.cancel, self.stats, self.backend = n, cancel, stats, backend

    def pool(self):
        """The process's pool with ``n`` workers, started if need be; None if it cannot be."""
        if self.stats["problem"] is not None:
            return None
        if self.backend is not None:
            return self.backend
        pool = _pool[0]
        if pool is None or not pool.alive() or pool.size != self.n:
            if pool is not None:
                pool.close()
            _pool[0] = None
            try:
                _pool[0] = pool = Pool(self.n)
            except WorkerError as exc:
                self.stats["problem"] = str(exc)
                return None
        return pool


class Deferred:
    """A value computed when first asked for (:meth:`result`), in the order the caller asks."""

    def __init__(self, get):
        self._get, self._value = get, None

    def result(self):
        if self._get is not None:
            self._value, self._get = self._get(), None
        return self._value

    def then(self, f):
        """A Deferred of ``f(self.result())``."""
        return Deferred(lambda: f(self.result()))


def ahead(items, start, depth=AHEAD):
    """(item, start(item)) for each of ``items``, in order, each yielded once the ``depth``
    items after it are started too: the caller uses one batch while the workers draw the next
    ``depth``. Items are started in order (their random rotations drawn in order), so the result
    does not depend on the timing."""
    started = collections.deque()
    for item in items:
        started.append((item, start(item)))
        if len(started) > depth:
            yield started.popleft()
    while started:
        yield started.popleft()


def submit(sc, eyes, frames, out, sky_out=None):
    """Start the rows of ``eyes`` on the workers; a Deferred that fills ``out`` (and, with a
    sky ``sc.sky``, ``sky_out``) and returns ``out``, or None when this call is not shared (no
    pool in use, too few eyes, no workers): the caller then computes the rows itself. Deferreds
    must be resolved in the order submitted. ``out`` must be zero (it is filled sparsely)."""
    context = getattr(_local, "context", None)
    if context is None or eyes.shape[0] < 2 * MIN_EYES:
        return None
    pool = context.pool()
    if pool is None:
        return None
    parts = min(context.n, eyes.shape[0] // MIN_EYES)
    try:
        job = pool.submit(sc, eyes, frames, parts)
    except WorkerError as exc:
        context.stats["problem"] = str(exc)
        return None
    stats = context.stats
    stats["processes"] = max(stats["processes"], parts)
    stats["calls"] += 1

    def collect():
        try:
            cpu = pool.cpu_seconds
            pool.collect(job, out, context.cancel, sky_out)
            _tally(stats, pool, cpu)
            return out
        except WorkerError as exc:     # a worker died or failed: this process does the rest
            stats["problem"] = str(exc)
            from .hemicube_chunk import rows_in_chunks
            rows_in_chunks(sc, eyes, frames, out, None, sky_out)
            return out
    return Deferred(collect)


def share(sc, eyes, frames, out, sky_out=None):
    """Fill ``out`` (and ``sky_out``) with the rows of ``eyes`` from the workers now; False
    when the call is not shared (see :func:`submit`)."""
    job = submit(sc, eyes, frames, out, sky_out)
    if job is None:
        return False
    job.result()
    return True


def share_rays(bvh, o, d, dn, t_max, any_mode):
    """(t, triangle) of every ray (:func:`core.raycast.cast`'s answer) computed by the workers,
    or None when the call is not shared (no pool in use, too few rays, another engine's
    backend, no workers): the caller then casts them itself."""
    context = getattr(_local, "context", None)
    if context is None or context.backend is not None or o.shape[0] < MIN_RAYS:
        return None
    pool = context.pool()
    if pool is None:
        return None
    parts = min(context.n, o.shape[0] // (MIN_RAYS // 2))
    stats, cpu = context.stats, pool.cpu_seconds
    try:
        hits = pool.collect_rays(pool.submit_rays(bvh, (o, d, dn, t_max), any_mode, parts),
                                 context.cancel)
    except WorkerError as exc:     # a worker died or failed: this process casts them
        stats["problem"] = str(exc)
        return None
    stats["processes"], stats["calls"] = max(stats["processes"], parts), stats["calls"] + 1
    _tally(stats, pool, cpu)
    return hits


def _tally(stats, pool, cpu):
    """Add a collected call's worker CPU time (the pool's since ``cpu``) and peak to ``stats``."""
    stats["cpu_seconds"] += pool.cpu_seconds - cpu
    if pool.peak_mb is not None:
        stats["peak_mb"] = round(max(pool.peak_mb, stats["peak_mb"] or 0.0), 1)


def set_backend(backend):
    """Share every bake's hemicube calls with ``backend`` from now on (None: this machine's
    worker processes again); the previous backend is returned.

    A backend is another engine's pool with :class:`Pool`'s interface: ``name``, ``size`` (the
    parts a call is cut into), ``pending`` (the submitted, uncollected jobs; empty when idle),
    ``cpu_seconds``, ``peak_mb``, ``submit(sc, eyes, frames, parts)`` -> job, ``collect(job,
    out, cancel, sky_out)`` (raising this module's :class:`WorkerError` on a failure and
    :class:`core.errors.BakeCancelled` on a cancel), ``alive()`` and ``close()``. Its parts
    run :func:`compute_part` (see ``radiosity_addon/cluster.py``: Dask distributed)."""
    previous, _backend[0] = _backend[0], backend
    return previous


def part_message(sc):
    """(geometry, scalars): what :func:`compute_part` needs of a kernel call ``sc`` besides its
    eyes, as plain data (the sky too: its class's module has another name in Blender)."""
    scalars = dict(n_patches=sc.n_patches, resolution=sc.r, cull_back=sc.cull_back,
                   near=sc.near, sky=None if sc.sky is None else sc.sky.message())
    return dict(vars(sc.geometry)), scalars


def compute_part(geometry, scalars, eyes, frames):
    """The rows of ``eyes`` (and their sky light, or None) from :func:`part_message`'s data,
    with this process's peak memory (MiB) and its CPU seconds: what a worker answers."""
    from .hemicube_chunk import Geometry, Scene, rows_in_chunks
    from .sky import from_message

    if not isinstance(geometry, Geometry):
        data, geometry = geometry, Geometry.__new__(Geometry)
        geometry.__dict__.update(data)
    sc = Scene(geometry, scalars["n_patches"], scalars["resolution"], scalars["cull_back"])
    sc.near = scalars["near"]
    sc.sky = from_message(scalars["sky"])
    tic = time.process_time()
    out = np.zeros((eyes.shape[0], 2 * sc.n_patches))
    sky_out = None if sc.sky is None else np.zeros((eyes.shape[0], 3))
    with _unshared():
        rows_in_chunks(sc, eyes, frames, out, None, sky_out)
    return out, sky_out, peak_mb(), time.process_time() - tic


def hit_columns(rows):
    """(columns, values): the columns of ``rows`` that hold a nonzero and those columns' values,
    what a worker sends back. A hemicube sees a few of the polygons, so this is a fraction of
    the dense rows (the office's gathers: 22 %), and the bake's process reads far fewer bytes;
    :meth:`Pool.collect` puts them back exactly."""
    hit = np.flatnonzero(np.any(rows != 0, axis=0))
    return hit, rows[:, hit]


@contextlib.contextmanager
def _unshared():
    """No sharing within: a part computes its own rows (a Dask worker may run in a process
    that has a backend set, or inside a bake)."""
    previous = getattr(_local, "context", None)
    _local.context = None
    try:
        yield
    finally:
        _local.context = previous


def close():
    """Stop the process's workers (they start again when next needed). Never waits long for
    a bake that holds them (at exit, a bake thread may still be running): it stops them then."""
    locked = _pool_lock.acquire(timeout=2.0)
    try:
        pool, _pool[0] = _pool[0], None
        if pool is not None:
            pool.close()
    finally:
        if locked:
            _pool_lock.release()


atexit.register(close)


def remember_cut(geometry, whole, sel, poly_patch):
    """Note that ``geometry`` is ``whole.cut(sel, poly_patch)``: a worker that holds ``whole``
    is sent the cut's numbers, not its arrays (for as long as ``geometry`` lives)."""
    _cuts[geometry] = (whole, sel, poly_patch)


def _small(ids):
    """``ids`` as int32 when they fit (half the bytes; the same values)."""
    return ids.astype(np.int32) if ids.size and ids.max() < 2 ** 31 else ids


def _token(geometry):
    """A number naming ``geometry`` (a core.hemicube_chunk.Geometry, or a core.raycast.BVH,
    which compares by value and so is kept by its id) for as long as it lives."""
    if hasattr(geometry, "__dataclass_fields__"):
        kept = _tree_tokens.get(id(geometry))
        if kept is None or kept[0]() is not geometry:
            kept = _tree_tokens[id(geometry)] = (weakref.ref(geometry), next(_next_token))
            for key in [k for k, (ref, _) in _tree_tokens.items() if ref() is None]:
                del _tree_tokens[key]
        return kept[1]
    token = _tokens.get(geometry)
    if token is None:
        token = _tokens[geometry] = next(_next_token)
    return token


class Pool:
    """``size`` worker processes, started and checked ready (WorkerError if they cannot be)."""

    def __init__(self, size):
        self.size = int(size)
        command = _command()
        env = dict(os.environ)
        # One thread per worker: the pool already fills the cores.
        for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[name] = "1"
        self.workers = []
        self.pending = collections.deque()      # ids of the jobs not yet collected
        self.ready = []                         # each worker's first message (pid, module)
        self.peak_mb = None                     # the workers' largest peak resident set, MiB
        self.cpu_seconds = 0.0                  # CPU time the workers spent on rows
        try:
            for _ in range(self.size):
                self.workers.append(_Worker(command, env))
            for worker in self.workers:
                try:
                    answer = worker.answers.get(timeout=START_TIMEOUT)
                except queue.Empty:
                    answer = None
                if not (isinstance(answer, tuple) and answer[0] == "ready"):
                    raise WorkerError(f"a worker process did not start ({command[0]}); see the "
                                      "console for its error")
                self.ready.append(answer[1])
        except BaseException:
            self.close()
            raise

    def alive(self):
        return bool(self.workers) and all(w.proc.poll() is None for w in self.workers)

    def close(self):
        self.pending.clear()
        workers, self.workers = self.workers, []
        for worker in workers:
            worker.kill()

    def submit(self, sc, eyes, frames, parts):
        """Send ``parts`` contiguous parts of ``eyes`` to the first ``parts`` workers; the job
        (the parts' bounds) for :meth:`collect`."""
        bounds = np.linspace(0, eyes.shape[0], parts + 1).round().astype(np.int64)
        _, scalars = part_message(sc)
        job = (next(_next_token), bounds)
        self.pending.append(job[0])
        try:
            for k in range(parts):
                worker = self.workers[k]
                token = self._hold(worker, sc.geometry)
                lo, hi = bounds[k], bounds[k + 1]
                worker.send(("rows", job[0], token, scalars, eyes[lo:hi], frames[lo:hi]))
        except (OSError, ValueError) as exc:
            self.close()
            raise WorkerError(f"a worker process stopped: {exc}") from exc
        return job

    def _hold(self, worker, geometry):
        """``geometry``'s token, sent to ``worker`` first if it does not hold it: as a cut of a
        Geometry it holds (sent first if need be), else whole. The worker keeps the last
        KEPT_GEOMETRIES it was sent, a cut's whole counting as sent again (:func:`serve` does
        the same, so both sides drop the same one)."""
        token = _token(geometry)
        if token in worker.kept:
            return token
        origin = _cuts.get(geometry)
        if origin is None:
            worker.send(("geometry", token, dict(vars(geometry))))
        else:
            whole, sel, poly_patch = origin
            source = self._hold(worker, whole)
            worker.kept.remove(source)
            worker.kept.append(source)
            worker.send(("cut", token, source, _small(sel), _small(poly_patch)))
        worker.kept.append(token)
        while len(worker.kept) > KEPT_GEOMETRIES:
            worker.kept.popleft()
        return token

    def submit_rays(self, bvh, rays, any_mode, parts):
        """Send ``parts`` contiguous parts of ``rays`` (origins, directions, their lengths,
        t_max) to the first ``parts`` workers, with ``bvh`` if they lack it; the job."""
        token = _token(bvh)
        bounds = np.linspace(0, rays[0].shape[0], parts + 1).round().astype(np.int64)
        job = (next(_next_token), bounds)
        self.pending.append(job[0])
        try:
            for k in range(parts):
                worker = self.workers[k]
                if token not in worker.kept_trees:
                    worker.send(("tree", token, dict(vars(bvh))))
                    worker.kept_trees.append(token)
                    if len(worker.kept_trees) > KEPT_TREES:
                        worker.kept_trees.popleft()
                lo, hi = bounds[k], bounds[k + 1]
                worker.send(("rays", job[0], token, [a[lo:hi] for a in rays], any_mode))
        except (OSError, ValueError) as exc:
            self.close()
            raise WorkerError(f"a worker process stopped: {exc}") from exc
        return job

    def collect_rays(self, job, cancel):
        """(t, triangle) of a job of :meth:`submit_rays`, the parts put back in order."""
        return tuple(np.concatenate(a) for a in zip(*(p[0] for p in self._collect(job, cancel))))

    def collect(self, job, out, cancel, sky_out=None):
        """The rows of a submitted ``job`` into ``out`` (returned), its sky light into
        ``sky_out`` (when it has a sky); BakeCancelled when ``cancel`` says so (the workers are
        killed), WorkerError when one fails. Jobs may be collected in any order (a worker
        answers in the order it was sent the jobs; answers to later jobs wait). ``out`` must
        be zero: the workers send the hit columns alone (:func:`hit_columns`)."""
        bounds = job[1]
        for k, ((hit, values), sky) in enumerate(self._collect(job, cancel)):
            out[bounds[k]:bounds[k + 1], hit] = values
            if sky_out is not None:
                sky_out[bounds[k]:bounds[k + 1]] = sky
        return out

    def _collect(self, job, cancel):
        """[(answer, extra)] of each part of ``job``, in order."""
        ident, bounds = job
        if not self.workers:
            raise WorkerError("the workers were stopped by an earlier failure")
        if ident not in self.pending:
            raise RuntimeError("this worker job was collected already, or never submitted")
        done = False
        try:
            parts = [self._answer(self.workers[k], ident, cancel)
                     for k in range(bounds.size - 1)]
            done = True
        finally:
            if done:
                self.pending.remove(ident)
            else:       # cancelled, failed or interrupted: the workers' state is unknown
                self.close()
        return parts

    def _answer(self, worker, ident, cancel):
        """The worker's answer to job ``ident``; answers to other jobs read meanwhile wait in
        ``worker.early``."""
        while ident not in worker.early:
            if cancel is not None and cancel():
                raise BakeCancelled("bake cancelled")
            try:
                answer = worker.answers.get(timeout=WAIT_STEP)
            except queue.Empty:
                continue
            if answer is None:
                raise WorkerError(f"worker process {worker.proc.pid} exited "
                                  f"(code {worker.proc.poll()})")
            if answer[0] == "error":
                raise WorkerError(f"worker process {worker.proc.pid} failed:\n{answer[1]}")
            worker.early[answer[5]] = answer
        answer = worker.early.pop(ident)
        if answer[2] is not None:
            self.peak_mb = max(self.peak_mb or 0.0, answer[2])
        self.cpu_seconds += answer[3]
        return answer[1], answer[4]


def serve():
    """A worker's main loop: answer messages on stdin until it closes."""
    from .hemicube_chunk import Geometry

    source = sys.stdin.buffer
    sink = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    # Stray prints go to stderr (or nowhere, when the parent had no console to hand on).
    err = sys.stderr.fileno() if sys.stderr is not None else os.open(os.devnull, os.O_WRONLY)
    os.dup2(err, sys.stdout.fileno())
    kept = collections.OrderedDict()
    trees = collections.OrderedDict()
    _send(sink, ("ready", dict(pid=os.getpid(), module=__name__, bpy="bpy" in sys.modules)))
    while True:
        message = _receive(source)
        if message is None:
            return
        try:
            if message[0] in ("geometry", "cut"):
                if message[0] == "geometry":
                    geometry = Geometry.__new__(Geometry)
                    geometry.__dict__.update(message[2])
                else:                                 # ("cut", token, whole's token, sel, items)
                    kept.move_to_end(message[2])
                    geometry = kept[message[2]].cut(message[3], message[4])
                kept[message[1]] = geometry
                while len(kept) > KEPT_GEOMETRIES:
                    kept.popitem(last=False)
                continue
            if message[0] == "tree":
                from .raycast import BVH
                trees[message[1]] = BVH(**message[2])
                while len(trees) > KEPT_TREES:
                    trees.popitem(last=False)
                continue
            if message[0] == "rays":
                from .raycast import cast
                _, ident, token, rays, any_mode = message
                tic = time.process_time()
                hits = cast(trees[token], *rays, any_mode)
                _send(sink, ("rays", hits, peak_mb(), time.process_time() - tic, None, ident))
                continue
            _, ident, token, scalars, eyes, frames = message
            out, sky_out, peak, cpu = compute_part(kept[token], scalars, eyes, frames)
            _send(sink, ("rows", hit_columns(out), peak, cpu, sky_out, ident))
        except Exception:                          # noqa: BLE001 - reported to the parent
            _send(sink, ("error", traceback.format_exc()))

