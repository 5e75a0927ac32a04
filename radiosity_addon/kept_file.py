"""A kept bake on disk, so Relight outlives the session: ``<name>.radiosity`` beside the .blend.

A bake's form factors live in memory (:mod:`radiosity_addon.relight`): hundreds of MB that a
.blend should not carry. With **Save Relight Data** on, saving the .blend also writes every
scene's kept bake beside it (:func:`save`, ``office.blend`` -> ``office.radiosity``), and a
Relight after reopening the file reads it back (:func:`load`) when nothing is kept in memory.
The batch writes it beside its output (``--save-relight``) and relights a baked file from it
(``--relight``).

The file: a line of JSON (its format and version, the package name it was written from, per
scene its baked objects' mesh fingerprints) and then a pickle of each scene's
:class:`relight.Kept`. Reading checks the fingerprints against the objects first, so a file
left from another bake of this .blend is refused before anything is read; the Relight itself
then compares the scene with the kept bake as in the session (``same.read``). The pickle is
read by an unpickler that admits only the add-on's own classes and NumPy's arrays and dtypes,
not arbitrary callables; still, read only files you made.
"""

import hashlib
import json
import os
import pickle
import weakref
from contextlib import contextmanager

import numpy as np

from .extract import ATTRIBUTE
from .same import RelightError

#: File name ending of a kept bake beside its .blend.
SUFFIX = ".radiosity"
MAGIC = "radiosity-kept"
FORMAT = 1

#: The package these modules run in (``radiosity_baker``; installed:
#: ``bl_ext.user_default.radiosity_baker``).
ROOT = __name__.rsplit(".", 2)[0]

#: Globals outside the add-on that kept bakes hold: NumPy's arrays and dtypes, plain containers.
_ALLOWED = {
    ("numpy", "dtype"), ("numpy", "ndarray"),
    ("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer"),
    ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
    ("copyreg", "_reconstructor"), ("builtins", "object"), ("builtins", "set"),
    ("builtins", "frozenset"), ("builtins", "complex"), ("builtins", "slice"),
    ("builtins", "bytearray"), ("collections", "OrderedDict"),
}


_HELD = [0]       # saves inside held() write no kept bake file
_WRITTEN = {}     # path -> {scene name: (weakref to the Kept written or read there, its prints)}


class KeptFileError(RelightError):
    """A kept bake file cannot be written or read; the message names the file."""


def beside(blend_path):
    """The kept bake file beside a .blend (``office.blend`` -> ``office.radiosity``)."""
    return os.path.splitext(blend_path)[0] + SUFFIX


def beside_blend(blend_path):
    """The kept bake file beside the .blend at ``blend_path`` when one is there; None when the
    .blend is unsaved (``""``) or has none beside it."""
    path = blend_path and beside(blend_path)
    return path if path and os.path.isfile(path) else None


def fingerprint(scene, names):
    """{object name: [vertex count, corner count, SHA-1 of its vertex coordinates and of its
    baked colours] or None (no such mesh object)} of the objects ``names`` (a kept bake's)."""
    out = {}
    for name in names:
        obj = scene.objects.get(name)
        if obj is None or obj.type != "MESH":
            out[name] = None
            continue
        mesh = obj.data
        co = np.empty(3 * len(mesh.vertices), np.float32)
        mesh.vertices.foreach_get("co", co)
        digest = hashlib.sha1(co.tobytes())
        colours = mesh.color_attributes.get(ATTRIBUTE)
        if colours is not None:
            rgba = np.empty(4 * len(colours.data), np.float32)
            colours.data.foreach_get("color", rgba)
            digest.update(rgba.tobytes())
        out[name] = [len(mesh.vertices), len(mesh.loops), digest.hexdigest()]
    return out


def save(path, scenes):
    """Write the kept bakes ``scenes`` ({scene: Kept}) to ``path`` (a temporary file renamed:
    an interrupted write leaves the old file). Returns the bytes written."""
    header = dict(format=MAGIC, version=FORMAT, root=ROOT,
                  scenes={scene.name: fingerprint(scene, _names(entry))
                          for scene, entry in scenes.items()})
    state = {scene.name: _state(entry) for scene, entry in scenes.items()}
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as fh:
            fh.write(json.dumps(header).encode() + b"\n")
            pickle.dump(state, fh, protocol=pickle.HIGHEST_PROTOCOL)
        size = os.path.getsize(tmp)
        os.replace(tmp, path)
        _WRITTEN[path] = {scene.name: (weakref.ref(entry), header["scenes"][scene.name])
                          for scene, entry in scenes.items()}
    except OSError as exc:
        raise KeptFileError(f"Relight data {path}: cannot write it ({exc.strerror or exc})") \
            from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return size


@contextmanager
def held():
    """Saves of the .blend inside this block write no kept bake file (:func:`with_blend`): the
    batch saves through a temporary file and writes its own beside its output."""
    _HELD[0] += 1
    try:
        yield
    finally:
        _HELD[0] -= 1


def with_blend(blend_path, scenes):
    """Write the kept bakes ``scenes`` ({scene: Kept}) beside a .blend being saved, unless
    :func:`held` or the file there already holds these very bakes. Returns the path written,
    or None."""
    if _HELD[0] or not blend_path or not scenes:
        return None
    path = beside(blend_path)
    done = _WRITTEN.get(path, {})
    if os.path.isfile(path) and set(done) == {s.name for s in scenes} and all(
            done[s.name][0]() is entry and done[s.name][1] == fingerprint(s, _names(entry))
            for s, entry in scenes.items()):
        return None
    save(path, scenes)
    return path


def _names(entry):
    return [part.object_name for part in entry.bake_input.extraction.parts]


def _state(entry):
    """The fields of a Kept worth keeping: not the calls, plans and hand-outs of a run."""
    from dataclasses import fields
    skip = ("calls", "made", "planning")
    return {f.name: getattr(entry, f.name) for f in fields(entry) if f.name not in skip}


def load(path, scene):
    """The Kept of ``scene`` in the file at ``path``. Raises KeptFileError naming the file when
    it is not a kept bake file, holds no bake of this scene, or holds another bake than the
    one the scene's objects show."""
    from .relight import Kept
    try:
        with open(path, "rb") as fh:
            try:
                header = json.loads(fh.readline())
            except ValueError:
                header = None
            if not isinstance(header, dict) or header.get("format") != MAGIC:
                raise KeptFileError(f"Relight data {path}: not a kept bake file")
            if header.get("version") != FORMAT:
                raise KeptFileError(f"Relight data {path}: written in format "
                                    f"{header.get('version')}, this add-on reads {FORMAT}; "
                                    f"bake again")
            prints = header.get("scenes", {})
            if scene.name not in prints:
                raise KeptFileError(f"Relight data {path}: it holds no bake of scene "
                                    f"'{scene.name}'; bake again")
            _check(path, scene, prints[scene.name])
            state = _Unpickler(fh, header.get("root") or ROOT).load()
    except FileNotFoundError:
        raise KeptFileError(f"no kept bake file at {path} (Save Relight Data in the panel, or "
                            f"the batch's --save-relight, writes one)") from None
    except OSError as exc:
        raise KeptFileError(f"Relight data {path}: cannot read it ({exc.strerror or exc})") \
            from None
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, TypeError) as exc:
        raise KeptFileError(f"Relight data {path}: unreadable ({exc}); bake again") from None
    entry = Kept(**state[scene.name])
    if set(state) == {scene.name}:
        _WRITTEN[path] = {scene.name: (weakref.ref(entry), prints[scene.name])}
    return entry


def _check(path, scene, prints):
    """The scene's baked objects are those the file's bake wrote (their mesh fingerprints)."""
    now = fingerprint(scene, list(prints))
    for name, saved in prints.items():
        if saved is None or now[name] is None:
            raise KeptFileError(f"Relight data {path}: object '{name}' of its bake is not "
                                f"in the scene; bake again")
        if now[name] != saved:
            raise KeptFileError(f"Relight data {path}: object '{name}' shows another bake "
                                f"than the one the file holds (baked or edited since it was "
                                f"written); bake again")


class _Unpickler(pickle.Unpickler):
    """Admits the add-on's own classes (under the package name they were written from, read
    in this one's) and :data:`_ALLOWED`; nothing else."""

    def __init__(self, fh, root):
        super().__init__(fh)
        self.root = root

    def find_class(self, module, name):
        if module == self.root or module.startswith(self.root + "."):
            module = ROOT + module[len(self.root):]
            found = super().find_class(module, name)
            if isinstance(found, type):
                return found
        elif (module, name) in _ALLOWED:
            try:
                return super().find_class(module, name)
            except (ImportError, AttributeError):   # NumPy 1.x reading 2.x's, and back
                other = module.replace("numpy._core", "numpy.core") if "_core" in module \
                    else module.replace("numpy.core", "numpy._core")
                return super().find_class(other, name)
        raise pickle.UnpicklingError(f"it refers to {module}.{name}, which a kept bake never "
                                     f"holds")


def relight_from(context, path):
    """The batch's --relight: the scene's kept bake read from ``path`` and relit with the light
    the scene holds now; (report, the kept bake's job.BakeInput). Raises RelightError."""
    from .relight import kept_or_file, relight
    entry = kept_or_file(context.scene, path)
    return relight(context), entry.bake_input


def save_scene(scene, blend_path):
    """The batch's --save-relight: the scene's kept bake beside the .blend saved at
    ``blend_path``; (its path, bytes). Raises KeptFileError when no bake is kept."""
    from .relight import kept, not_kept_reason
    entry = kept(scene)
    if entry is None:
        reason = not_kept_reason(scene)
        raise KeptFileError(f"the bake was not kept for Relight ({reason}); raise --memory-budget"
                            if reason else "no bake of this scene is kept for Relight")
    path = beside(blend_path)
    return path, save(path, {scene: entry})
