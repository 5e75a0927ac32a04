"""Measured luminous intensity distributions: IES LM-63 and EULUMDAT (.ldt) files.

Both formats store a table of luminous intensity (candela) over *type C* angles: gamma, the polar
angle from the luminaire's nadir (0 = straight down its axis, 180 = straight up), and C, the
azimuth of the vertical half-plane, 0..360 degrees. A file may store only part of the C range and
declare a symmetry; :class:`Photometry` holds the table expanded to the full circle, in absolute
candela, and interpolates it bilinearly (C periodic; 0 beyond the table's gamma range).

* :func:`read_ies` reads LM-63 1986, 1991, 1995, 2002 and 2019 files: keyword lines up to
  ``TILT=``, then numbers separated by blanks, commas or line ends, wrapped anywhere. ``TILT=NONE``
  and ``TILT=INCLUDE`` (the tilt table is read and not used: the lamp is taken in the position it
  was measured in, as Cycles does); photometric type C only. Candela = value x candela multiplier
  x ballast factor (x the ballast-lamp factor of 1986 and 1991 files; the slot is "future use"
  from 1995 and the file generation type in 2019). Last horizontal angle 0: axially symmetric;
  90: symmetric in each quadrant; 180: about the C0-C180 plane; first 90 and last 270: about the
  C90-C270 plane (LM-63-1995); above 180: no symmetry.
* :func:`read_ldt` reads EULUMDAT: fixed lines (the header, one line per lamp-set field), then the
  direct ratios, the C angles, the gamma angles and the stored planes' intensities in cd/klm,
  scaled by the first lamp set's flux. The symmetry indicator Isym 0..4 says which planes are
  stored: all, one (axial), C0..C180, C90..C270, C0..C90.
* :func:`read_photometry` picks the reader by the file's extension.

Bad input raises :class:`core.errors.SceneError` naming the file, the line and what was wrong.
How a light uses a distribution (orientation, scale) is :mod:`core.lights`' business.
"""

import os
from dataclasses import dataclass

import numpy as np

from .errors import SceneError

#: Cycles' IES Texture node turns candela into the power (W) of the isotropic point light of that
#: intensity: 4 pi / 177.83, the luminous efficacy of the D65 illuminant (lm/W)
#: (intern/cycles/util/ies.cpp).
CYCLES_CANDELA_TO_WATT = 4.0 * np.pi / 177.83

#: Angles (deg) closer than this are the same angle (symmetry planes, duplicated C planes); gamma
#: within this of the table's ends still reads the end value.
ANGLE_TOL = 1e-6

SYMMETRIES = ("none", "axial", "c0-c180", "c90-c270", "quadrant")

# The mirrors that rebuild the full circle from the stored planes, applied in turn, each to the
# planes gathered so far: C -> 360 - C mirrors in the C0-C180 plane, C -> 180 - C in C90-C270.
_MIRRORS = {"none": (), "c0-c180": (360.0,), "c90-c270": (180.0,), "quadrant": (180.0, 360.0)}

# Where each EULUMDAT symmetry's stored planes start and how many there are, from Mc.
_LDT_PLANES = {0: (lambda mc: 0, lambda mc: mc, "none"),
               1: (lambda mc: 0, lambda mc: 1, "axial"),
               2: (lambda mc: 0, lambda mc: mc // 2 + 1, "c0-c180"),
               3: (lambda mc: mc // 4, lambda mc: mc // 2 + 1, "c90-c270"),
               4: (lambda mc: 0, lambda mc: mc // 4 + 1, "quadrant")}


@dataclass(frozen=True, eq=False)
class Photometry:
    """A luminous intensity distribution over the sphere, type C angles, absolute candela.

    Build with :func:`read_ies`, :func:`read_ldt` or :meth:`from_planes`.

    Attributes
    ----------
    name : str
        The file's name (for messages).
    gamma : (G,) float64
        Polar angles (deg) from the nadir, ascending, within [0, 180].
    c : (C,) float64
        Azimuths (deg), ascending, covering one full turn: ``c[-1] == c[0] + 360`` (0 and 360 for
        every file whose planes include C0).
    candela : (C, G) float64
        Intensity (cd) at ``(c[k], gamma[i])``; the last row repeats the first.
    symmetry : str
        One of :data:`SYMMETRIES`: what the file declared.
    lamp_lumens : float or None
        The lamps' flux the file states (lm); None for absolute photometry (LM-63 lumens -1).
    output_ratio : float or None
        The light output ratio the file states (EULUMDAT LORL / 100); None if not stated.
    """

    name: str
    gamma: np.ndarray
    c: np.ndarray
    candela: np.ndarray
    symmetry: str
    lamp_lumens: object = None
    output_ratio: object = None

    @classmethod
    def from_planes(cls, name, gamma, c, candela, symmetry, lamp_lumens=None, output_ratio=None):
        """A distribution from the stored planes and the declared symmetry.

        Parameters
        ----------
        name : str
        gamma : (G,) array_like
            Polar angles (deg), strictly ascending, within [0, 180]; G >= 2.
        c : (S,) array_like
            The stored planes' azimuths (deg), strictly ascending.
        candela : (S, G) array_like
            Intensity (cd) >= 0 per stored plane and polar angle.
        symmetry : str
            'axial' (S = 1), 'quadrant' (C0..C90), 'c0-c180' (C0..C180), 'c90-c270' (C90..C270)
            or 'none' (any planes of one turn; the turn is closed periodically).

        Raises
        ------
        SceneError
            Naming ``name`` and what is wrong.
        """
        gamma = np.asarray(gamma, dtype=np.float64).reshape(-1)
        c = np.asarray(c, dtype=np.float64).reshape(-1)
        cd = np.asarray(candela, dtype=np.float64)
        if symmetry not in SYMMETRIES:
            raise SceneError(f"{name}: symmetry must be one of {SYMMETRIES}; got {symmetry!r}")
        if cd.shape != (c.size, gamma.size):
            raise SceneError(f"{name}: candela must have shape (C planes, vertical angles) = "
                             f"({c.size}, {gamma.size}); got {cd.shape}")
        if gamma.size < 2:
            raise SceneError(f"{name}: needs at least 2 vertical angles; got {gamma.size}")
        if not np.all(np.isfinite(cd)) or np.any(cd < 0):
            k, i = np.argwhere(~(cd >= 0) | ~np.isfinite(cd))[0]
            raise SceneError(f"{name}: candela values must be finite and >= 0; got {cd[k, i]} "
                             f"at C {c[k]:g}, gamma {gamma[i]:g}")
        _check_ascending(name, "vertical angles", gamma)
        if gamma[0] < -ANGLE_TOL or gamma[-1] > 180 + ANGLE_TOL:
            raise SceneError(f"{name}: vertical angles must lie in [0, 180] degrees (type C); "
                             f"got {gamma[0]:g}..{gamma[-1]:g}")
        _check_ascending(name, "horizontal angles", c)
        want = {"axial": None, "quadrant": (0.0, 90.0), "c0-c180": (0.0, 180.0),
                "c90-c270": (90.0, 270.0)}.get(symmetry)
        if symmetry == "axial":
            if c.size != 1:
                raise SceneError(f"{name}: an axially symmetric distribution has 1 plane; "
                                 f"got {c.size}")
            c_full, cd_full = np.array([0.0, 360.0]), np.repeat(cd, 2, axis=0)
        else:
            if want is not None and (abs(c[0] - want[0]) > ANGLE_TOL
                                     or abs(c[-1] - want[1]) > ANGLE_TOL):
                raise SceneError(f"{name}: symmetry {symmetry} stores the planes C{want[0]:g}.."
                                 f"C{want[1]:g}; got C{c[0]:g}..C{c[-1]:g}")
            if symmetry == "none" and c[-1] - c[0] > 360 + ANGLE_TOL:
                raise SceneError(f"{name}: horizontal angles must span at most 360 degrees; got "
                                 f"{c[0]:g}..{c[-1]:g}")
            c_full, cd_full = _expand(c, cd, _MIRRORS[symmetry])
        return cls(name, gamma, c_full, cd_full, symmetry,
                   None if lamp_lumens is None else float(lamp_lumens),
                   None if output_ratio is None else float(output_ratio))

    def intensity(self, gamma, c):
        """Intensity (cd) in the directions ``(gamma, c)`` (radians, broadcast together).

        Bilinear in gamma and C (C periodic), 0 where gamma lies outside the table's range.
        """
        g = np.degrees(np.asarray(gamma, dtype=np.float64))
        h = np.degrees(np.asarray(c, dtype=np.float64))
        g, h = np.broadcast_arrays(g, h)
        G, C, cd = self.gamma, self.c, self.candela
        i = np.clip(np.searchsorted(G, g, side="right") - 1, 0, G.size - 2)
        t = np.clip((g - G[i]) / (G[i + 1] - G[i]), 0.0, 1.0)
        h = C[0] + np.mod(h - C[0], 360.0)
        k = np.clip(np.searchsorted(C, h, side="right") - 1, 0, C.size - 2)
        u = np.clip((h - C[k]) / (C[k + 1] - C[k]), 0.0, 1.0)
        # a + t (b - a): exact at t = 0, and between equal planes (axial files, mirror images)
        v0 = cd[k, i] + t * (cd[k, i + 1] - cd[k, i])
        v1 = cd[k + 1, i] + t * (cd[k + 1, i + 1] - cd[k + 1, i])
        value = v0 + u * (v1 - v0)
        inside = (g >= G[0] - ANGLE_TOL) & (g <= G[-1] + ANGLE_TOL)
        return np.where(inside, value, 0.0)

    def flux(self):
        """Total luminous flux (lm): the integral over the sphere of :meth:`intensity`, exact.

        Per cell of the table the interpolant is linear in gamma and in C, so the integral of
        ``I sin(gamma) dgamma dC`` has closed-form weights (linear in gamma against sin, trapezoid
        in C).
        """
        a, b = np.radians(self.gamma[:-1]), np.radians(self.gamma[1:])
        h = b - a
        wa = (h * np.cos(a) + np.sin(a) - np.sin(b)) / h      # int (b - g) / h sin g dg over [a, b]
        wb = (np.sin(b) - np.sin(a) - h * np.cos(b)) / h      # int (g - a) / h sin g dg
        zonal = self.candela[:, :-1] @ wa + self.candela[:, 1:] @ wb          # (C,)
        dc = np.radians(np.diff(self.c))
        return float(np.sum(dc * (zonal[:-1] + zonal[1:]) / 2.0))


def _check_ascending(name, what, x):
    if x.size and not np.all(np.isfinite(x)):
        raise SceneError(f"{name}: {what} must be finite numbers; got {x.tolist()}")
    bad = np.flatnonzero(np.diff(x) <= 0)
    if bad.size:
        j = bad[0]
        raise SceneError(f"{name}: {what} must be strictly ascending; got {x[j]:g} then "
                         f"{x[j + 1]:g}")


def _expand(c, cd, mirrors):
    """The stored planes and their mirror images over the full turn, sorted, the turn closed by
    a copy of the first plane 360 degrees on."""
    cs, rows = c, cd
    for m in mirrors:
        cs, rows = np.concatenate([cs, m - cs]), np.concatenate([rows, rows])
    if mirrors:
        cs = np.mod(cs, 360.0)
        cs = np.where(cs > 360.0 - ANGLE_TOL, 0.0, cs)
    order = np.argsort(cs, kind="stable")
    cs, rows = cs[order], rows[order]
    keep = np.concatenate([[True], np.diff(cs) > ANGLE_TOL])
    cs, rows = cs[keep], rows[keep]
    if cs[-1] - cs[0] >= 360.0 - ANGLE_TOL:           # the file lists both 0 and 360
        cs, rows = cs[:-1], rows[:-1]
    return np.append(cs, cs[0] + 360.0), np.concatenate([rows, rows[:1]])


def _source(path_or_text, what):
    """(name, text) of a path or of the text itself (anything with a line break)."""
    if isinstance(path_or_text, str) and ("\n" in path_or_text or "\r" in path_or_text):
        return f"<{what} text>", path_or_text
    try:
        path = os.fspath(path_or_text)
    except TypeError:
        raise SceneError(f"{what} file must be a path or the file's text; got "
                         f"{type(path_or_text).__name__}") from None
    name = os.path.basename(path) or str(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise SceneError(f"{name}: cannot read {path!s}: {e.strerror or e}") from None
    # Latin-1 decodes any byte: keyword lines carry degree signs and accents in many encodings.
    return name, data.decode("latin-1")


class _Tokens:
    """Numbers separated by blanks, commas or line ends, with the line each came from."""

    def __init__(self, name, lines, first_line):
        self.name = name
        self.items = [(tok, first_line + n)
                      for n, line in enumerate(lines)
                      for tok in line.replace(",", " ").split()]
        self.pos = 0

    def take(self, count, what, integer=False):
        """(count,) float64 (or one value if count is None) of the next tokens."""
        n = 1 if count is None else int(count)
        if self.pos + n > len(self.items):
            got = len(self.items) - self.pos
            where = (f" from line {self.items[self.pos][1]}" if got
                     else f" after line {self.items[-1][1]}" if self.items else "")
            raise SceneError(f"{self.name}: expected {n} {what}{where}; got {got} "
                             "(the file ends)")
        out = np.empty(n)
        for j, (tok, line) in enumerate(self.items[self.pos:self.pos + n]):
            try:
                out[j] = float(tok)
            except ValueError:
                raise SceneError(f"{self.name} line {line}: expected a number ({what}); got "
                                 f"{tok!r}") from None
            if integer and out[j] != round(out[j]):
                raise SceneError(f"{self.name} line {line}: {what} must be a whole number; got "
                                 f"{tok!r}")
        self.pos += n
        return float(out[0]) if count is None else out

    def rest(self):
        return self.items[self.pos:]


def read_ies(path_or_text):
    """Read an IES LM-63 file (type C photometry) into a :class:`Photometry`.

    Parameters
    ----------
    path_or_text : str or os.PathLike
        A path, or the file's text (a string with a line break).

    Returns
    -------
    Photometry

    Raises
    ------
    SceneError
        Naming the file, the line and what is wrong (no ``TILT=`` line, a count that the numbers
        do not fill, a type A or B file, angles out of order...).
    """
    name, text = _source(path_or_text, "IES")
    lines = text.splitlines()
    tilt = next((n for n, line in enumerate(lines)
                 if line.strip().upper().startswith("TILT")), None)
    if tilt is None:
        raise SceneError(f"{name}: no TILT= line; not an IES LM-63 file")
    version = lines[0].strip().upper() if lines else ""
    mode = lines[tilt].split("=", 1)[1].strip().upper() if "=" in lines[tilt] else ""
    tok = _Tokens(name, lines[tilt + 1:], tilt + 2)
    if mode == "INCLUDE":
        tok.take(None, "lamp-to-luminaire geometry")
        pairs = tok.take(None, "number of tilt angles", integer=True)
        tok.take(pairs, "tilt angles")
        tok.take(pairs, "tilt multiplying factors")
    elif mode != "NONE":
        raise SceneError(f"{name} line {tilt + 1}: TILT={lines[tilt].split('=', 1)[-1].strip()}"
                         " (tilt data in another file) is not supported; TILT=NONE or INCLUDE")
    lamps = tok.take(None, "number of lamps")
    lumens = tok.take(None, "lumens per lamp")
    multiplier = tok.take(None, "candela multiplier")
    n_v = int(tok.take(None, "number of vertical angles", integer=True))
    n_h = int(tok.take(None, "number of horizontal angles", integer=True))
    ptype = int(tok.take(None, "photometric type", integer=True))
    tok.take(4, "units type and luminous dimensions")
    ballast, second, _watts = tok.take(3, "ballast factor, future use and input watts")
    if ptype != 1:
        kind = {2: "type B", 3: "type A"}.get(ptype, "unknown")
        raise SceneError(f"{name}: photometric type {ptype} ({kind}) is not supported; only "
                         "type C (1)")
    if n_v < 2 or n_h < 1:
        raise SceneError(f"{name}: needs at least 2 vertical and 1 horizontal angle; got "
                         f"{n_v} and {n_h}")
    gamma = tok.take(n_v, "vertical angles")
    c = tok.take(n_h, "horizontal angles")
    values = tok.take(n_v * n_h, f"candela values ({n_h} planes x {n_v} vertical angles)")
    extra = [(t, line) for t, line in tok.rest() if _is_number(t)]
    if extra:
        raise SceneError(f"{name} line {extra[0][1]}: {len(extra)} numbers after the candela "
                         f"table ({n_h} planes x {n_v} vertical angles): do the counts match?")
    factor = multiplier * ballast
    if not (version.startswith("IESNA:LM-63-1995") or version.startswith("IESNA:LM-63-2002")
            or version.startswith("IES:LM-63-2019")):
        factor *= second                # 1986 and 1991: the ballast-lamp photometric factor
    if not factor > 0:
        raise SceneError(f"{name}: candela multiplier x ballast factor must be > 0; got "
                         f"{factor:g}")
    if n_h == 1:
        symmetry = "axial"
    elif abs(c[0]) <= ANGLE_TOL and abs(c[-1] - 90) <= ANGLE_TOL:
        symmetry = "quadrant"
    elif abs(c[0]) <= ANGLE_TOL and abs(c[-1] - 180) <= ANGLE_TOL:
        symmetry = "c0-c180"
    elif abs(c[0] - 90) <= ANGLE_TOL and abs(c[-1] - 270) <= ANGLE_TOL:
        symmetry = "c90-c270"
    elif abs(c[0]) <= ANGLE_TOL and 180 < c[-1] <= 360 + ANGLE_TOL:
        symmetry = "none"
    else:
        raise SceneError(f"{name}: horizontal angles must run 0 (one angle), 0..90, 0..180, "
                         f"90..270 or 0..(180, 360]; got {c[0]:g}..{c[-1]:g}")
    return Photometry.from_planes(name, gamma, c, values.reshape(n_h, n_v) * factor, symmetry,
                                  lamp_lumens=lamps * lumens if lumens > 0 else None)


def _is_number(tok):
    try:
        float(tok)
    except ValueError:
        return False
    return True


def read_ldt(path_or_text):
    """Read a EULUMDAT (.ldt) file into a :class:`Photometry` (cd/klm x the first lamp set's
    flux / 1000).

    Parameters
    ----------
    path_or_text : str or os.PathLike
        A path, or the file's text (a string with a line break).

    Returns
    -------
    Photometry

    Raises
    ------
    SceneError
        Naming the file, the line and what is wrong.
    """
    name, text = _source(path_or_text, "EULUMDAT")
    lines = text.splitlines()

    def field(n, what, integer=False):
        """The number on line n (1-based)."""
        if n > len(lines):
            raise SceneError(f"{name}: the file ends at line {len(lines)}; expected {what} on "
                             f"line {n}")
        raw = lines[n - 1].strip().replace(",", ".")
        try:
            value = float(raw)
        except ValueError:
            raise SceneError(f"{name} line {n}: expected {what} (a number); got "
                             f"{lines[n - 1].strip()!r}") from None
        if integer and value != round(value):
            raise SceneError(f"{name} line {n}: {what} must be a whole number; got {raw!r}")
        return int(round(value)) if integer else value

    isym = field(3, "Isym (symmetry indicator)", integer=True)
    mc = field(4, "Mc (number of C-planes)", integer=True)
    ng = field(6, "Ng (intensities per C-plane)", integer=True)
    if isym not in _LDT_PLANES:
        raise SceneError(f"{name} line 3: Isym (symmetry indicator) must be 0..4; got {isym}")
    if mc < 1 or ng < 2:
        raise SceneError(f"{name} lines 4 and 6: needs Mc >= 1 C-planes and Ng >= 2 "
                         f"intensities per plane; got Mc {mc}, Ng {ng}")
    step = {2: 2, 3: 4, 4: 4}.get(isym, 1)
    if mc % step:
        raise SceneError(f"{name} line 4: Mc (number of C-planes) must be a multiple of {step} "
                         f"with Isym {isym}; got {mc}")
    lorl = field(23, "LORL (light output ratio, %)")
    sets = field(26, "n (number of lamp sets)", integer=True)
    if sets < 1:
        raise SceneError(f"{name} line 26: n (number of lamp sets) must be >= 1; got {sets}")
    flux = field(29, "the first lamp set's total luminous flux (lm)")
    if not flux > 0:
        raise SceneError(f"{name} line 29: the lamps' luminous flux must be > 0 lm; got {flux:g}")
    start = 26 + 6 * sets                 # 0-based index of the first direct ratio's line
    first, count, symmetry = _LDT_PLANES[isym]
    planes = count(mc)
    # One number a line: a lone comma is a decimal comma (European writers).
    tok = _Tokens(name, [line.replace(",", ".") if "." not in line and line.count(",") == 1
                         else line for line in lines[start:]], start + 1)
    tok.take(10, "direct ratios (DR)")
    c_all = tok.take(mc, "C angles")
    gamma = tok.take(ng, "gamma angles")
    values = tok.take(planes * ng, f"intensities ({planes} C-planes x {ng} gamma angles, "
                                   f"Isym {isym})")
    extra = [(t, line) for t, line in tok.rest() if _is_number(t)]
    if extra:
        raise SceneError(f"{name} line {extra[0][1]}: {len(extra)} numbers after the intensity "
                         f"table ({planes} C-planes x {ng}, Isym {isym}): do Mc, Ng and Isym "
                         "match?")
    c = c_all[first(mc):first(mc) + planes]
    return Photometry.from_planes(name, gamma, c, values.reshape(planes, ng) * (flux / 1000.0),
                                  symmetry, lamp_lumens=flux, output_ratio=lorl / 100.0)


def read_photometry(path):
    """:func:`read_ies` or :func:`read_ldt` by the file's extension (.ies, .ldt; any case)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == ".ies":
        return read_ies(path)
    if ext == ".ldt":
        return read_ldt(path)
    raise SceneError(f"{os.path.basename(os.fspath(path))}: photometric files must be .ies "
                     f"(IES LM-63) or .ldt (EULUMDAT); got {ext or 'no extension'!r}")
