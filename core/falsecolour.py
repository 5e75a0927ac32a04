"""False colour for illuminance: lux -> a fixed perceptual ramp, with a legend's round ticks.

Lighting software shows computed illuminance as false colour over a scale with a legend
(DIALux's false colours, Radiance's ``falsecolor``). The scale here:

* **Ramp.** Matplotlib's *viridis* (CC0, van der Walt and Smith 2015), sampled at 17 points and
  interpolated linearly between them: dark blue -> teal -> green -> yellow. Its lightness rises
  monotonically, so brighter always reads as more lux, also in grey print and for the common
  colour-vision deficiencies. Colours are sRGB display values in [0, 1].
* **Top.** The lux at the top of the ramp: a value the user gives, or *auto*: the smallest round
  number (:data:`LINEAR_MANTISSAS` or, in log mode, :data:`LOG_MANTISSAS` x a power of ten) at or
  above the :data:`AUTO_PERCENTILE` th percentile of the values, weighted by the area each value
  stands for when weights are given (the add-on weights each corner by its share of its face):
  at most 5 % of the surface is above the top. A percentile, not the maximum: hot spots (the
  ceiling a few centimetres from a luminaire, a wall right by a spot light) would otherwise push
  the whole room into the bottom colours; on the bundled office the maximum is 24000 lx, 95 % of
  the surface below 1330 lx. Values above the top take the top colour (clipped, as
  ``falsecolor`` does).
* **Linear** mode maps ``0 .. top`` onto the ramp; ticks every round step (1, 2, 2.5 or 5 x a
  power of ten), 4 to 8 intervals when the top is auto. **Log** mode maps ``top / 10^decades ..
  top`` (:data:`LOG_DECADES` decades) by ``log10``: ten times the lux is ``1 / decades`` of the
  ramp higher; ticks at every decade. Values at or below the bottom take the bottom colour.

Inputs are never mutated; everything computes in float64.
"""

import math
from dataclasses import dataclass

import numpy as np

from .settings import Choice, Setting

#: The ramp's control points (sRGB, 0..1), evenly spaced: viridis entries 0, 16, ..., 240, 255.
RAMP = np.array([
    (0.267004, 0.004874, 0.329415),
    (0.282327, 0.094955, 0.417331),
    (0.278826, 0.175490, 0.483397),
    (0.258965, 0.251537, 0.524736),
    (0.229739, 0.322361, 0.545706),
    (0.199430, 0.387607, 0.554642),
    (0.172719, 0.448791, 0.557885),
    (0.149039, 0.508051, 0.557250),
    (0.127568, 0.566949, 0.550556),
    (0.120638, 0.625828, 0.533488),
    (0.157851, 0.683765, 0.501686),
    (0.246070, 0.738910, 0.452024),
    (0.369214, 0.788888, 0.382914),
    (0.515992, 0.831158, 0.294279),
    (0.678489, 0.863742, 0.189503),
    (0.845561, 0.887322, 0.099702),
    (0.993248, 0.906157, 0.143936),
])

#: Auto top: this percentile of the values (by weight), rounded up.
AUTO_PERCENTILE = 95.0
#: Auto top in linear mode: these x a power of ten (each has a round step giving 4 to 8 ticks).
LINEAR_MANTISSAS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0)
#: Auto top in log mode: these x a power of ten (so every decade tick is round too).
LOG_MANTISSAS = (1.0, 2.0, 5.0)
#: Round tick steps: these x a power of ten.
STEP_MANTISSAS = (1.0, 2.0, 2.5, 5.0)
#: Decades a log scale spans below its top.
LOG_DECADES = 3
#: Linear ticks: intervals wanted between 0 and the top (and the range allowed).
TICK_INTERVALS = (5, 4, 8)
#: Top used when no value is above zero (an unlit scene): 1 lx.
UNLIT_TOP = 1.0
#: Relative tolerance of "a multiple of the step" (float rounding of round numbers).
_EXACT = 1e-9

SCALES = (
    Choice("linear", "Linear", "Lux in equal steps from 0 to the top (reads like a plan's "
           "isolux values)"),
    Choice("log", "Logarithmic", f"Each decade of lux the same length, {LOG_DECADES} decades "
           "below the top (daylight and deep rooms)"),
)

#: The display's settings, declared once (the panel's properties and the batch options come
#: from these rows, as the bake's do from core.settings.TABLE).
SETTINGS = (
    Setting("lux_scale", "choice", "linear", "Lux Scale",
            "How illuminance maps onto the false-colour ramp", choices=SCALES),
    Setting("lux_max", "float", None, "Lux Max",
            "Illuminance at the top of the false-colour ramp (more is drawn in the top colour); "
            "auto (0 in the panel): a round number at or above the lux of 95 percent of the "
            "surface",
            unit="lx", low=0, open_low=True, soft=(1.0, 10000.0), auto=True),
)


def _values(lux, name="lux"):
    """(n,) float64 of finite values, or ValueError naming the argument."""
    arr = np.asarray(lux, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must have shape (n,); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {int((~np.isfinite(arr)).sum())} "
                         "NaN or infinite value(s)")
    return arr


def ramp(t):
    """(n, 3) sRGB colours of ramp positions ``t`` (n,) in [0, 1] (clipped)."""
    t = np.clip(_values(t, "t"), 0.0, 1.0)
    knots = np.linspace(0.0, 1.0, RAMP.shape[0])
    return np.stack([np.interp(t, knots, RAMP[:, c]) for c in range(3)], axis=1)


def _round(value):
    """*value* without the float noise of products like 3 x 0.1 (12 significant digits)."""
    return float(f"{value:.12g}")


def round_up(value, mantissas):
    """Smallest ``m x 10^k`` (m in *mantissas*, ascending) at or above *value* > 0."""
    if not (value > 0 and math.isfinite(value)):
        raise ValueError(f"value must be a finite number > 0; got {value!r}")
    k = math.floor(math.log10(value))
    for power in (k, k + 1):
        for m in mantissas:
            candidate = _round(m * 10.0 ** power)
            if candidate >= value * (1 - _EXACT):
                return candidate
    raise AssertionError("unreachable: 1 x 10^(k+1) is above value")


def linear_ticks(top):
    """Round tick values from 0 to *top* (a linear scale).

    The step is the round number (:data:`STEP_MANTISSAS`) that divides *top* into 4 to 8 equal
    intervals, nearest 5. A top no round step divides (a user's 750 lx) gets the multiples of a
    round step of about top / 5 and the top itself as the last tick (the multiple just below it
    is dropped when nearer than half a step).
    """
    if not (top > 0 and math.isfinite(top)):
        raise ValueError(f"top must be a finite number > 0; got {top!r}")
    k = math.floor(math.log10(top))
    steps = [_round(m * 10.0 ** p) for p in (k - 2, k - 1, k) for m in STEP_MANTISSAS]
    want, low, high = TICK_INTERVALS
    exact = [s for s in steps if low <= top / s <= high
             and abs(top / s - round(top / s)) < _EXACT * top / s]
    if exact:
        step = min(exact, key=lambda s: (abs(top / s - want), s))
        n = int(round(top / step))
        return tuple(_round(i * step) for i in range(n + 1))
    step = min(steps, key=lambda s: (abs(math.log(top / s / want)), s))
    ticks = [_round(i * step) for i in range(int(top / step * (1 + _EXACT)) + 1)]
    if top - ticks[-1] < 0.5 * step and len(ticks) > 1:
        ticks.pop()
    return tuple(ticks) + (_round(top),)


def log_ticks(top, decades=LOG_DECADES):
    """Tick values of a log scale: ``top x 10^-k`` for k = decades .. 0 (ascending)."""
    return tuple(_round(top * 10.0 ** -k) for k in range(decades, -1, -1))


@dataclass(frozen=True)
class Scale:
    """A false-colour scale.

    Attributes
    ----------
    mode : {'linear', 'log'}
    top : float
        Lux at the top of the ramp.
    bottom : float
        Lux at the bottom: 0 (linear) or ``top / 10^decades`` (log).
    ticks : tuple of float
        The legend's values, ascending, from ``bottom`` to ``top``.
    """

    mode: str
    top: float
    bottom: float
    ticks: tuple

    def position(self, lux):
        """(n,) ramp positions in [0, 1] of illuminance ``lux`` (n,) (clipped at both ends)."""
        lux = _values(lux)
        if self.mode == "linear":
            t = lux / self.top
        else:
            floor = np.maximum(lux, self.bottom)       # log10 of <= 0 is never taken
            t = np.log10(floor / self.bottom) / np.log10(self.top / self.bottom)
        return np.clip(t, 0.0, 1.0)

    def colours(self, lux):
        """(n, 3) sRGB false colours of ``lux`` (n,)."""
        return ramp(self.position(lux))

    def tick_colours(self):
        """(k, 3) sRGB colours of the ticks."""
        return self.colours(np.asarray(self.ticks, dtype=np.float64))

    def labels(self):
        """The ticks as text: shortest plain decimals ('0', '2.5', '1000'), no exponent."""
        return tuple(label(v) for v in self.ticks)

    def as_dict(self):
        """JSON-friendly form (the report, the legend the viewport draws)."""
        return dict(mode=self.mode, top=self.top, bottom=self.bottom, ticks=list(self.ticks),
                    labels=list(self.labels()), colours=self.tick_colours().tolist())


def label(value):
    """A tick value as short plain text: 1000.0 -> '1000', 0.25 -> '0.25'."""
    return np.format_float_positional(float(value), precision=6, trim="-")


def percentile(values, q, weights=None):
    """The weighted *q* th percentile (inverted CDF): the smallest of ``values`` (n,) whose
    weights, with those of all smaller values, make at least q % of the total. ``weights`` (n,)
    >= 0, default all 1 (then numpy's ``method='inverted_cdf'``)."""
    values = _values(values, "values")
    weights = np.ones_like(values) if weights is None else _values(weights, "weights")
    if weights.shape != values.shape or np.any(weights < 0) or not weights.sum() > 0:
        raise ValueError(f"weights must be (n,) >= 0 with a positive sum for {values.shape[0]} "
                         f"values; got shape {weights.shape}, sum {weights.sum()}")
    order = np.argsort(values, kind="stable")
    share = np.cumsum(weights[order])
    k = np.searchsorted(share, q / 100.0 * share[-1] * (1 - _EXACT), side="left")
    return float(values[order][min(k, values.size - 1)])


def make_scale(lux, mode="linear", top=None, decades=LOG_DECADES, weights=None):
    """The scale for illuminance values ``lux``.

    Parameters
    ----------
    lux : (n,) array_like of float
        Illuminance (lx) the scale is for; only used when ``top`` is None (n may be 0).
    mode : {'linear', 'log'}
    top : float, optional
        Lux at the top of the ramp (> 0); None: auto (see the module's docstring).
    decades : int
        Log mode: decades below the top (>= 1).
    weights : (n,) array_like of float, optional
        What each value stands for in the auto top's percentile (the area of its surface).

    Returns
    -------
    Scale
    """
    SETTINGS[0].check(mode)
    if top is not None:
        SETTINGS[1].check(top)
        top = float(top)
    if not (isinstance(decades, (int, np.integer)) and not isinstance(decades, bool)
            and decades >= 1):
        raise ValueError(f"decades must be an integer >= 1; got {decades!r}")
    if top is None:
        values = _values(lux)
        high = percentile(values, AUTO_PERCENTILE, weights) if values.size else 0.0
        mantissas = LINEAR_MANTISSAS if mode == "linear" else LOG_MANTISSAS
        top = round_up(high, mantissas) if high > 0 else UNLIT_TOP
    if mode == "linear":
        return Scale("linear", top, 0.0, linear_ticks(top))
    return Scale("log", top, _round(top * 10.0 ** -decades), log_ticks(top, decades))
