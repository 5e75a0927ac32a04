"""The pipes to a worker process: length-prefixed pickles over its stdin and stdout.

:class:`_Worker` starts one worker (:func:`_command`) and keeps a thread that writes its
messages and one that reads its answers into a queue; :mod:`core.parallel` runs the pool.
"""

import collections
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading

_HEADER = struct.Struct("<Q")


class WorkerError(RuntimeError):
    """A worker could not start, or failed; the message carries its own traceback."""


def _command():
    """The command that starts one worker, or WorkerError when no interpreter can be found."""
    exe = sys.executable or ""
    if "python" not in os.path.basename(exe).lower():
        base = getattr(sys, "_base_executable", "") or ""
        exe = base if "python" in os.path.basename(base).lower() else ""
    if not exe or not os.path.exists(exe):
        raise WorkerError(f"no Python interpreter to start workers with (sys.executable is "
                          f"{sys.executable!r})")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    code = (f"import sys; sys.path.insert(0, {root!r}); "
            "from core.parallel import serve; serve()")
    return [exe, "-c", code]


def _send(stream, message):
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def _receive(stream):
    """The next message, or None at the end of the stream."""
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        return None
    (size,) = _HEADER.unpack(head)
    data = stream.read(size)
    if len(data) < size:
        return None
    return pickle.loads(data)


class _Worker:
    """One worker process, a thread that reads its answers into a queue (portable: waiting on a
    queue with a timeout works on every platform, select on pipes does not), and a thread that
    writes the messages for it, so that the bake never waits on a full pipe while the worker
    still computes the previous call."""

    def __init__(self, command, env):
        # No console window per worker on Windows (Blender runs without one).
        flags = getattr(subprocess, "CREATE_NO_WINDOW", 0) if sys.platform == "win32" else 0
        self.proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     env=env, creationflags=flags)
        self.answers = queue.Queue()
        self.outbox = queue.Queue()
        self.kept = collections.deque()         # geometry tokens the worker holds, oldest first
        self.kept_trees = collections.deque()   # ray-casting tree tokens, likewise
        self.early = {}                         # job id -> an answer not collected yet
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.writer = threading.Thread(target=self._write, daemon=True)
        self.writer.start()

    def _write(self):
        while True:
            data = self.outbox.get()
            if data is None:
                return
            try:
                self.proc.stdin.write(_HEADER.pack(len(data)))
                self.proc.stdin.write(data)
                self.proc.stdin.flush()
            except (OSError, ValueError):       # the worker is gone: the reader reports it
                return

    def _read(self):
        try:
            while True:
                message = _receive(self.proc.stdout)
                self.answers.put(message)
                if message is None:
                    return
        except (OSError, ValueError, EOFError, pickle.UnpicklingError):
            self.answers.put(None)

    def send(self, message):
        self.outbox.put(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.outbox.put(None)
        try:
            self.proc.stdin.close()
        except (OSError, ValueError):
            pass
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            pass
