"""The cause of a chart error: a small camera pipeline fitted to the 24 patch means.

A render or photo of the chart that misses its reference was usually made by one of a few
mistakes: too much or too little light (exposure), light added to every patch (ambient light,
flare, a lifted black level), a colour cast (white balance), turned hues (a wrong colour
matrix), too much or too little colour (saturation), a tone curve (a view transform such as Filmic or AgX, a contrast look), or an
encoding mistake (sRGB values taken as linear). :func:`diagnose` fits this pipeline, in linear
light, from the reference patches ``r`` (linear sRGB, negatives clipped to 0: the albedos a
renderer can hold) to the measured patch means ``m``::

    x = g r / (g . w)            white-balance gains g = (g_R, 1, g_B), luminance kept
    x = R(h) x                   hue rotation by h degrees about the grey axis (1, 1, 1)
    x = Y + s (x - Y)            saturation s about the grey axis (Y the luminance of x)
    x = 2^EV x + b               exposure EV, black offset b (linear units of white: Y = 1)
    m = T(x)                     tone curve T: none, a view transform, a power law, ...

(an encoding mistake of the reflectances, ``r -> enc(r)``, acts on ``r`` first; a display-
referred image, an 8- or 16-bit PNG or a JPEG, is clipped to [0, 1] last, a scene-linear one
to 0 and above; the measured values alike). The tone curves
are the neutral curves of common view transforms (:func:`view_transforms`: Blender's Standard
looks, Filmic and AgX with their looks, ACES 1.3 and 2.0, Khronos PBR Neutral, sampled from
Blender 5.0.1's OpenColorIO config by ``benchmarks/tools/view_transforms.py``), applied per
channel between an inset and an outset matrix; the sRGB encoding and decoding (the two
encoding mistakes); a power law about white (gamma); and an unknown tone curve (contrast
about mid grey and a highlight shoulder, 2 parameters).

**Model selection.** The residuals are the CIELAB differences of the 3 coordinates of every
patch used (N = 3 n). Each candidate model (a subset of exposure, black offset, white balance,
hue and saturation, with one tone curve) is fitted by least squares and scored by the Bayesian
information criterion with a known noise scale::

    C = RSS / σ² + ln(N) p

``p`` the model's parameters (the choice of a tone curve counts 1, its shape parameters
one each: a named curve 1, a power law 2, the unknown curve 3), ``σ²`` the
larger of :data:`NOISE_FLOOR_LAB` squared and the residual variance of the largest model
(Mallows' estimate of the noise from the full model). From the base model, forward selection
adds the part (or tone curve) that lowers ``C`` most, if it also lowers the mean ΔE00 by
:data:`MIN_REMOVED_DELTA_E`, until none does; the parts of that model are the causes, each with
the mean ΔE00 the model loses without it, when together they remove at least
:data:`MIN_EXPLAINED_SHARE` of the error (else the error is no pipeline's: a camera's colour
matrix or spectral sensitivities move each patch its own way, and no cause is named). A
chart whose patches match the reference within ``σ`` (the base model's root-mean-square
residual at most :data:`NOISE_FLOOR_LAB`) has no systematic cause: no spurious parameter is
reported for a correct render.

**Exposure.** With a fixed exposure (``--exposure``, a manifest), the base model has the
expected exposure and an exposure error is a cause like the others; with the audit's
automatic exposure it is a free parameter of every model, reported but not a cause.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import field, replace
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour import colorimetry as cm
from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

F64 = NDArray[np.float64]

#: The pipeline's parts that can be a cause, in the order they are reported.
CAUSES: tuple[str, ...] = ("tone", "exposure", "black-offset", "white-balance", "hue",
                           "saturation")
#: Noise scale floor σ of the criterion, CIELAB units per coordinate: a quarter of a
#: just-noticeable difference, above the rounding of an 8-bit image's patch means (about 0.1).
NOISE_FLOOR_LAB = 0.25
#: Tone curves kept from the screening (the best fits of exposure and curve alone) for the
#: full search.
TONE_CANDIDATES = 3
#: Least share of the mean ΔE00 the chosen model must remove for its parts to be named the
#: cause (below: an error no part of the model explains, e.g. a camera's colour matrix).
MIN_EXPLAINED_SHARE = 0.5
#: Least lowering of the mean ΔE00 for a part to be added to the model (a part that removes
#: less is no finding, whatever the criterion says).
MIN_REMOVED_DELTA_E = 0.05
#: White level (of the reference white) below which the unknown tone curve's shoulder is
#: named highlight compression.
GENERIC_SHOULDER = 4.0
#: Luminance weights of linear sRGB (the Y row of the IEC 61966-2-1 matrix).
LUMINANCE: F64 = np.asarray(cm.MATRIX_LINEAR_SRGB_TO_XYZ[1], np.float64)
#: The view-transform data file (in ``fidelity/data``).
VIEW_TRANSFORMS_FILE = "view-transforms.json"
#: Scene mid grey, the pivot of the view transforms' neutral curves.
MID_GREY = 0.18


# --------------------------------------------------------------------------------------------
# Tone curves
# --------------------------------------------------------------------------------------------


@record
class ToneCurve:
    """A tone curve of the cause model.

    Attributes
    ----------
    name
        How the report names it (``AgX``, ``Filmic, Medium High Contrast``, ``gamma``...).
    family
        ``agx``, ``filmic``, ``standard`` (a contrast look on Blender's Standard view),
        ``aces``, ``neutral`` (Khronos PBR Neutral), ``encoding``, ``gamma`` (a power on
        the reflectances), ``display-gamma`` (an image encoded with a pure power, read as
        sRGB) or ``generic``.
    params
        Free shape parameters fitted (0 for a named curve).
    penalty
        Parameters it counts in the criterion: its choice and its shape parameters (a named
        curve 1, the power laws 2, the unknown curve 3).
    reflectance
        True: it acts on the reflectances, before the light (an encoding mistake of the
        albedos); False: on the scene-linear values, after exposure and offset.
    function
        ``f(x, theta)``: linear values (..., 3) and the shape parameters -> linear values;
        ``theta`` (params,), or (k, params) for a stack ``x`` (k, n, 3), one row per chart.
    """

    name: str
    family: str
    params: int
    penalty: int
    reflectance: bool
    function: Callable[[F64, F64], F64] = field(repr=False, compare=False)

    def __call__(self, x: F64, theta: F64) -> F64:
        """The curve applied to ``x`` (..., 3) with shape parameters ``theta``."""
        return self.function(x, theta)


def _view_curve(stops: F64, neutral: F64, inset: F64, outset: F64) -> Callable[[F64, F64], F64]:
    log_y = np.log2(np.maximum(neutral, 1e-12))

    def apply(x: F64, theta: F64) -> F64:
        mixed = np.maximum(x @ inset.T, 1e-12)
        u = np.log2(mixed / MID_GREY)
        return np.asarray(2.0 ** np.interp(u, stops, log_y) @ outset.T, np.float64)

    return apply


@cache
def view_transforms() -> tuple[ToneCurve, ...]:
    """The named view transforms of :data:`VIEW_TRANSFORMS_FILE`: per channel, the neutral
    curve (display-linear sRGB out per scene-linear Rec.709 in) between the inset and the
    outset matrices (module docstring)."""
    doc = json.loads((resource_dir("data") / VIEW_TRANSFORMS_FILE).read_text(encoding="utf-8"))
    s = doc["stops"]
    stops = np.arange(float(s["start"]), float(s["stop"]) + float(s["step"]) / 2,
                      float(s["step"]))
    out = []
    for t in doc["transforms"]:
        neutral = np.asarray(t["neutral"], np.float64)
        if neutral.shape != stops.shape:
            raise InvalidValueError(f"{VIEW_TRANSFORMS_FILE}: {t['name']}: {neutral.size} "
                                    f"samples for {stops.size} stops")
        out.append(ToneCurve(str(t["name"]), str(t["family"]), 0, 1, False, _view_curve(
            stops, neutral, np.asarray(t["inset"], np.float64),
            np.asarray(t["outset"], np.float64))))
    return tuple(out)


def _srgb_encoded(x: F64, theta: F64) -> F64:
    return np.asarray(cm.delinearize_srgb(np.clip(x, 0.0, None)), np.float64)


def _srgb_decoded(x: F64, theta: F64) -> F64:
    return np.asarray(cm.linearize_srgb(np.clip(x, 0.0, None)), np.float64)


def _shape(theta: F64, j: int) -> Any:
    """Shape parameter ``j`` of ``theta`` (params,) (a number) or (k, params) (k, 1, 1): one
    per chart of a (k, n, 3) stack."""
    v = theta[..., j]
    return v[..., None, None] if np.ndim(v) else v


def _gamma(x: F64, theta: F64) -> F64:
    return np.asarray(np.power(np.clip(x, 0.0, None), np.exp(_shape(theta, 0))), np.float64)


def _display_gamma(x: F64, theta: F64) -> F64:
    """Encoded with a pure power ``1 / γ`` (``γ = 2.2 exp(theta[0])``), decoded as sRGB."""
    gamma = 2.2 * np.exp(_shape(theta, 0))
    encoded = np.power(np.clip(x, 0.0, None), 1.0 / gamma)
    return np.asarray(cm.linearize_srgb(encoded), np.float64)


def _generic(x: F64, theta: F64) -> F64:
    """Contrast ``c = exp(theta[0])`` about mid grey and a shoulder ``K = theta[1]^2``:
    ``0.18 (1 + K) u / (1 + K u)``, ``u = (x / 0.18)^c`` (Naka-Rushton; white level
    0.18 (1 + K) / K; K = 0: a power law about mid grey)."""
    u = np.power(np.clip(x, 0.0, None) / MID_GREY, np.exp(_shape(theta, 0)))
    k = _shape(theta, 1) * _shape(theta, 1)
    return np.asarray(MID_GREY * (1.0 + k) * u / (1.0 + k * u), np.float64)


#: The tone curves other than the view transforms.
ENCODING_MISTAKES: tuple[ToneCurve, ...] = (
    ToneCurve("sRGB-encoded values used as linear", "encoding", 0, 1, True, _srgb_encoded),
    ToneCurve("linear values decoded as sRGB", "encoding", 0, 1, True, _srgb_decoded),
    ToneCurve("gamma", "gamma", 1, 2, True, _gamma),
    ToneCurve("display gamma", "display-gamma", 1, 2, False, _display_gamma),
)
GENERIC_CURVE = ToneCurve("tone curve", "generic", 2, 3, False, _generic)


def tone_curves() -> tuple[ToneCurve, ...]:
    """Every tone curve of the model: the encoding mistakes, the power law, the view
    transforms and the unknown curve."""
    return (*ENCODING_MISTAKES, *view_transforms(), GENERIC_CURVE)


# --------------------------------------------------------------------------------------------
# The pipeline model
# --------------------------------------------------------------------------------------------


#: The parts of the model other than the tone curve: (name, cause kind, parameters).
PARTS: tuple[tuple[str, str, int], ...] = (
    ("exposure", "exposure", 1), ("offset", "black-offset", 1),
    ("balance", "white-balance", 2), ("hue", "hue", 1), ("saturation", "saturation", 1))


@record
class _Spec:
    """Which parts a model has: exposure free, offset, white balance, hue rotation,
    saturation, and its tone curve."""

    exposure: bool = False
    offset: bool = False
    balance: bool = False
    hue: bool = False
    saturation: bool = False
    tone: ToneCurve | None = None

    @property
    def size(self) -> int:
        return (sum(n for name, _, n in PARTS if getattr(self, name))
                + (self.tone.params if self.tone else 0))

    def penalty(self, exposure_counts: bool) -> int:
        return (sum(n for name, _, n in PARTS if getattr(self, name)
                    and (name != "exposure" or exposure_counts))
                + (self.tone.penalty if self.tone else 0))

    def flags(self) -> dict[str, bool]:
        return {name: bool(getattr(self, name)) for name, _, _ in PARTS}

    def with_part(self, name: str, on: bool = True) -> _Spec:
        return _Spec(**(self.flags() | {name: on}), tone=self.tone)

    def without(self, kind: str) -> _Spec:
        if kind == "tone":
            return replace(self, tone=None)
        off = {name: False for name, k, _ in PARTS if k == kind}
        return _Spec(**(self.flags() | off), tone=self.tone)


def _unpack(spec: _Spec, theta: F64, expected_ev: float) -> dict[str, Any]:
    i = 0
    p: dict[str, Any] = {"ev": expected_ev, "offset": 0.0, "gains": (1.0, 1.0), "hue": 0.0,
                         "saturation": 1.0, "tone": np.zeros(0)}
    if spec.exposure:
        p["ev"] = float(theta[i])
        i += 1
    if spec.offset:
        p["offset"] = float(theta[i])
        i += 1
    if spec.balance:
        p["gains"] = (math.exp(float(theta[i])), math.exp(float(theta[i + 1])))
        i += 2
    if spec.hue:
        p["hue"] = float(theta[i])
        i += 1
    if spec.saturation:
        p["saturation"] = math.exp(float(theta[i]))
        i += 1
    if spec.tone is not None:
        p["tone"] = np.asarray(theta[i:i + spec.tone.params], np.float64)
    return p


def _tone_start(tone: ToneCurve) -> list[float]:
    return [0.0] * (tone.params - 1) + [0.0 if tone.params == 1 else 0.3] if tone.params else []


def _pack(spec: _Spec, p: Mapping[str, Any]) -> F64:
    """Inverse of :func:`_unpack`: the parameter vector of ``spec`` from values ``p`` (a
    parent model's: a warm start)."""
    theta: list[float] = []
    if spec.exposure:
        theta.append(float(p["ev"]))
    if spec.offset:
        theta.append(float(p["offset"]))
    if spec.balance:
        theta += [math.log(p["gains"][0]), math.log(p["gains"][1])]
    if spec.hue:
        theta.append(float(p["hue"]))
    if spec.saturation:
        theta.append(math.log(p["saturation"]))
    if spec.tone is not None and spec.tone.params:
        shape = np.asarray(p["tone"], np.float64)
        theta += list(shape) if shape.size == spec.tone.params else _tone_start(spec.tone)
    return np.asarray(theta, np.float64)


def hue_rotation(degrees: float) -> F64:
    """The 3 x 3 rotation of linear RGB by ``degrees`` about the grey axis (1, 1, 1)
    (Rodrigues' formula; +120° takes red to green, as the hue angle turns)."""
    t = math.radians(degrees)
    n = np.full(3, 1.0 / math.sqrt(3.0))
    return np.asarray(math.cos(t) * np.eye(3) + math.sin(t) * _CROSS
                      + (1.0 - math.cos(t)) * np.outer(n, n), np.float64)


#: The cross-product matrix of the grey axis (1, 1, 1) / sqrt(3).
_CROSS: F64 = np.array([[0.0, -1.0, 1.0], [1.0, 0.0, -1.0], [-1.0, 1.0, 0.0]]) / math.sqrt(3.0)


def _hue_rotations(degrees: F64) -> F64:
    """:func:`hue_rotation` of each of ``degrees`` (k,): (k, 3, 3)."""
    t = np.radians(degrees)[:, None, None]
    n = np.full(3, 1.0 / math.sqrt(3.0))
    return np.asarray(np.cos(t) * np.eye(3) + np.sin(t) * _CROSS
                      + (1.0 - np.cos(t)) * np.outer(n, n), np.float64)


def _predict(spec: _Spec, theta: F64, reference: F64, expected_ev: float,
             display: bool) -> F64:
    """The model ``spec`` at parameters ``theta`` (p,) -> the chart (n, 3); at a stack of
    parameters (k, p) -> the charts (k, n, 3), one evaluation for all (a Jacobian's
    columns). The parameters of one chart are numbers, of a stack (k, 1, 1) columns."""
    t = np.asarray(theta, np.float64)
    single = t.ndim == 1

    def column(j: int) -> Any:
        return float(t[j]) if single else t[:, j, None, None]

    def exp(v: Any) -> Any:
        return math.exp(v) if single else np.exp(v)

    x: F64 = reference if single else np.broadcast_to(reference, (len(t), *reference.shape))
    i = 0
    ev: Any = expected_ev
    offset: Any = 0.0
    if spec.exposure:
        ev, i = column(i), i + 1
    if spec.offset:
        offset, i = column(i), i + 1
    tone = spec.tone
    shape = t[..., spec.size - tone.params:] if tone is not None else t[..., :0]
    if tone is not None and tone.reflectance:
        x = tone(x, shape)
    if spec.balance:
        if single:
            g = np.array([exp(column(i)), 1.0, exp(column(i + 1))])
        else:
            g = np.stack([np.exp(t[:, i]), np.ones(len(t)), np.exp(t[:, i + 1])], axis=-1)
        x = x * (g / (g @ LUMINANCE)[..., None])[..., None, :]
        i += 2
    if spec.hue:
        x = x @ (hue_rotation(column(i)).T if single
                 else np.swapaxes(_hue_rotations(t[:, i]), 1, 2))
        i += 1
    if spec.saturation:
        y = (x @ LUMINANCE)[..., None]
        x = y + exp(column(i)) * (x - y)
        i += 1
    x = x * 2.0 ** ev + offset
    if tone is not None and not tone.reflectance:
        x = tone(x, shape)
    return np.clip(x, 0.0, 1.0 if display else None)


def _lab(linear: F64) -> F64:
    return np.asarray(cm.xyz_to_lab(cm.linear_srgb_to_xyz(linear)), np.float64)


@record
class _Fit:
    spec: _Spec
    theta: F64
    rss: float

    def predict(self, problem: _Problem) -> F64:
        return _predict(self.spec, self.theta, problem.reference, problem.expected_ev,
                        problem.display)


@record
class _Problem:
    reference: F64
    target_lab: F64
    used: NDArray[np.bool_]
    expected_ev: float
    display: bool
    #: the measured patches as the chart ΔE sees them: scaled by the exposure the audit
    #: applied, sRGB-encoded and clipped to [0, 1], as CIELAB
    chart_lab: F64
    applied_scale: float

    @property
    def n(self) -> int:
        return 3 * int(self.used.sum())

    def residual(self, spec: _Spec, theta: F64) -> F64:
        """The used patches' Lab residuals (3 m,) at ``theta`` (p,); (k, 3 m) at (k, p)."""
        pred = _predict(spec, theta, self.reference, self.expected_ev, self.display)
        d = (_lab(pred) - self.target_lab)[..., self.used, :]
        return np.asarray(d.reshape(*d.shape[:-2], -1), np.float64)

    def start(self, spec: _Spec, ev: float | None = None) -> F64:
        """Every parameter of ``spec`` at its identity, the exposure at ``ev`` (default: the
        expected one)."""
        return _pack(spec, {"ev": self.expected_ev if ev is None else ev, "offset": 0.0,
                            "gains": (1.0, 1.0), "hue": 0.0, "saturation": 1.0,
                            "tone": np.zeros(0)})

    def fit(self, spec: _Spec, start: F64 | None = None) -> _Fit:
        theta0 = self.start(spec) if start is None else start
        if theta0.size == 0:
            r = self.residual(spec, theta0)
            return _Fit(spec, theta0, float(r @ r))
        lo, hi = _bounds(spec)

        def residual(t: F64) -> F64:
            return self.residual(spec, t)

        theta, rss = least_squares(residual, theta0, lo, hi, vectorised=True)
        return _Fit(spec, theta, rss)

    def best_ev(self, spec: _Spec) -> tuple[float, float]:
        """The exposure, on a quarter-stop grid over +-12 EV about the expected one, that fits
        ``spec`` (its other parts at their identity) best, and its residual sum of squares:
        a start for the least squares."""
        evs = self.expected_ev + np.arange(-12.0, 12.01, 0.25)
        theta = self.start(spec)
        tone = spec.tone
        shape = theta[len(theta) - tone.params:] if tone is not None else theta[:0]
        x = self.reference
        if tone is not None and tone.reflectance:
            x = tone(x, shape)
        x = x[None] * (2.0 ** evs)[:, None, None]
        if tone is not None and not tone.reflectance:
            x = tone(x, shape)
        if self.display:
            x = np.clip(x, 0.0, 1.0)
        d = (_lab(x) - self.target_lab)[:, self.used]
        rss = np.sum(d * d, axis=(1, 2))
        k = int(np.argmin(rss))
        return float(evs[k]), float(rss[k])


def least_squares(residual: Callable[[F64], F64], start: F64, lo: F64, hi: F64, *,
                  iterations: int = 100, tolerance: float = 1e-10,
                  vectorised: bool = False) -> tuple[F64, float]:
    """Minimise ``sum(residual(theta)**2)`` over ``lo <= theta <= hi`` by Levenberg-Marquardt
    (Marquardt's scaling of the damping by the diagonal of JᵀJ), with a forward-difference
    Jacobian and the steps clipped to the bounds; stops when the sum of squares falls by less
    than ``tolerance`` relatively, or no damped step lowers it. Returns the parameters and the
    sum of squares. ``vectorised``: ``residual`` also takes a stack of parameter vectors
    (k, p) and returns their residuals (k, n), so that the Jacobian's columns come from one
    call. (SciPy's solvers are not imported by an audit: their import alone takes longer than
    the fit.)"""
    x = np.clip(np.asarray(start, np.float64), lo, hi)
    r = residual(x)
    cost = float(r @ r)
    damping = 1e-3
    for _ in range(iterations):
        h = 1e-6 * np.maximum(1.0, np.abs(x))
        step_to = np.where(x + h <= hi, x + h, x - h)
        shifted = np.repeat(x[None], x.size, axis=0)  # row i: x with its i-th part moved
        shifted[np.arange(x.size), np.arange(x.size)] = step_to
        if vectorised:
            moved = residual(shifted)
        else:
            moved = np.stack([residual(row) for row in shifted])
        jac = ((moved - r) / (step_to - x)[:, None]).T
        a, g = jac.T @ jac, jac.T @ r
        scale = np.diag(a) + 1e-12
        for _ in range(12):
            try:
                step = np.linalg.solve(a + damping * np.diag(scale), -g)
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            xn = np.clip(x + step, lo, hi)
            rn = residual(xn)
            cn = float(rn @ rn)
            if cn < cost:
                break
            damping *= 4.0
        else:
            return x, cost
        done = cost - cn <= tolerance * max(cost, 1e-300)
        x, r, cost = xn, rn, cn
        damping = max(damping / 3.0, 1e-12)
        if done:
            break
    return x, cost


def _bounds(spec: _Spec) -> tuple[F64, F64]:
    lo: list[float] = []
    hi: list[float] = []
    if spec.exposure:
        lo.append(-30.0)
        hi.append(30.0)
    if spec.offset:
        lo.append(-1.0)
        hi.append(10.0)
    if spec.balance:
        lo += [-3.0, -3.0]
        hi += [3.0, 3.0]
    if spec.hue:
        lo.append(-180.0)
        hi.append(180.0)
    if spec.saturation:
        lo.append(-4.0)
        hi.append(3.0)
    if spec.tone is not None and spec.tone.params:
        lo += [-3.0] * spec.tone.params
        hi += [3.0] * spec.tone.params
    return np.asarray(lo, np.float64), np.asarray(hi, np.float64)


# --------------------------------------------------------------------------------------------
# The diagnosis
# --------------------------------------------------------------------------------------------


@record
class Cause:
    """One cause of a chart error (a part of the fitted model).

    Attributes
    ----------
    kind
        One of :data:`CAUSES`.
    text
        The cause in words and numbers, with units (``exposure +2.00 EV: ...``).
    values
        Its fitted values: ``ev`` (EV), ``offset`` (linear units of white, Y = 1),
        ``red_gain``/``blue_gain`` (ratios to green), ``hue_degrees``, ``saturation`` (a
        factor), the tone curve's ``gamma``, ``contrast`` or ``white``.
    delta_e_removed
        How much higher the mean ΔE00 of the model is without this cause, >= 0 (ΔE00 units).
    tone_curve
        The tone curve's name (a ``tone`` cause), else None.
    """

    kind: str
    text: str
    values: Mapping[str, float]
    delta_e_removed: float
    tone_curve: str | None = None

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"kind": self.kind, "text": self.text, "values": dict(self.values),
                "delta_e_removed": self.delta_e_removed, "tone_curve": self.tone_curve}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Cause:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["kind"]), str(d["text"]),
                   {str(k): float(v) for k, v in dict(d["values"]).items()},
                   float(d["delta_e_removed"]),
                   None if d.get("tone_curve") is None else str(d["tone_curve"]))


@record
class Diagnosis:
    """What most likely made a chart's error (:func:`diagnose`).

    Attributes
    ----------
    causes
        The causes found, in :data:`CAUSES` order; empty: no systematic cause.
    delta_e
        Mean ΔE00 of the base model (the reference, gamut-clipped, at the expected exposure)
        against the measured patches, over the patches used, both as the chart ΔE sees them
        (scaled by the audit's exposure correction, sRGB-encoded, clipped to [0, 1]).
    residual_delta_e
        Mean ΔE00 the fitted model leaves, the same way.
    exposure_ev
        The fitted exposure: relative to the expected one when ``exposure_fixed`` (an
        error), else the image's own (what the automatic exposure normalises), EV.
    exposure_fixed
        Whether the exposure was fixed (an exposure error is then a cause).
    display_referred
        Whether the image was taken as display-referred (clipped to [0, 1]).
    sigma
        The noise scale σ of the criterion, CIELAB units per coordinate.
    patches
        Patches fitted.
    notes
        What the model cannot explain by design (a reference outside the sRGB gamut), in
        words.
    within_noise
        Whether the patches match the reference within the noise floor (the base model's
        root-mean-square residual at most ``sigma``): nothing to explain. False with no
        cause: an error no part of the model explains.
    """

    causes: tuple[Cause, ...]
    delta_e: float
    residual_delta_e: float
    exposure_ev: float
    exposure_fixed: bool
    display_referred: bool
    sigma: float
    patches: int
    notes: tuple[str, ...] = ()
    within_noise: bool = False

    @property
    def systematic(self) -> bool:
        """Whether a cause was found."""
        return bool(self.causes)


    def cause(self, kind: str) -> Cause | None:
        """The cause of ``kind``, None when not found."""
        return next((c for c in self.causes if c.kind == kind), None)

    def summary(self) -> str:
        """One line: the causes, or that there is none; with an automatic exposure, the
        image's exposure it normalised away."""
        if self.within_noise:
            text = (f"no systematic cause: the patches match the reference within the "
                    f"measurement (σ {self.sigma:.2f} in CIELAB)")
        elif not self.causes:
            text = ("no systematic cause: the error differs from patch to patch, as a "
                    "camera's colour matrix or spectral sensitivities make it, not as exposure, "
                    "black offset, white balance, saturation or a tone curve would")
        else:
            text = "; ".join(c.text for c in self.causes)
        if not self.exposure_fixed:
            text += (f"; the image's exposure, {self.exposure_ev:+z.2f} EV, is normalised away "
                     f"by the automatic exposure (a fixed --exposure judges it)")
        return text

    def lines(self) -> list[str]:
        """The causes one a line, then how much of the error they explain and the notes."""
        if not self.causes:
            return [self.summary(), *self.notes]
        return [*(c.text for c in self.causes),
                f"the model leaves mean ΔE00 {self.residual_delta_e:.2f} of "
                f"{self.delta_e:.2f}", *self.notes]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, and ``summary``."""
        return {"summary": self.summary(), "causes": [c.to_json() for c in self.causes],
                "delta_e": self.delta_e, "residual_delta_e": self.residual_delta_e,
                "exposure_ev": self.exposure_ev, "exposure_fixed": self.exposure_fixed,
                "display_referred": self.display_referred, "sigma": self.sigma,
                "patches": self.patches, "notes": list(self.notes),
                "within_noise": self.within_noise}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Diagnosis:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(Cause.from_json(c) for c in d["causes"]), float(d["delta_e"]),
                   float(d["residual_delta_e"]), float(d["exposure_ev"]),
                   bool(d["exposure_fixed"]), bool(d["display_referred"]), float(d["sigma"]),
                   int(d["patches"]), tuple(str(n) for n in d.get("notes") or ()),
                   bool(d.get("within_noise", False)))


def _chart_lab(linear: F64, scale: float) -> F64:
    """CIELAB of linear values as the chart ΔE sees them: scaled, encoded and clipped."""
    encoded = np.clip(cm.delinearize_srgb(linear * scale), 0.0, 1.0)
    return np.asarray(cm.srgb_to_lab(encoded), np.float64)


def _mean_delta_e(problem: _Problem, fit: _Fit) -> float:
    """Mean ΔE00 of the model's patches against the measured ones, both as the chart ΔE sees
    them (:func:`_chart_lab`)."""
    lab = _chart_lab(fit.predict(problem), problem.applied_scale)
    return float(np.mean(np.asarray(cm.delta_e_2000(lab, problem.chart_lab),
                                    np.float64)[problem.used]))


def _tone_words(tone: ToneCurve, theta: F64) -> tuple[str, dict[str, float]]:
    if tone.family == "encoding":
        if tone.function is _srgb_encoded:
            return ("gamma / encoding: sRGB-encoded values used as linear (colours or "
                    "textures written without decoding, e.g. sRGB base colours as linear "
                    "factors)"), {}
        return "gamma / encoding: linear values decoded as sRGB (decoded twice)", {}
    if tone.family == "gamma":
        g = math.exp(float(theta[0]))
        return (f"gamma / encoding: a power {g:.3f} on linear light, white kept (e.g. "
                f"gamma 2.2 against the sRGB curve, or a wrong encoding)"), {"gamma": g}
    if tone.family == "display-gamma":
        g = 2.2 * math.exp(float(theta[0]))
        return (f"gamma / encoding: the image was encoded with a pure power 1/{g:.2f} "
                f"(gamma {g:.2f}) and is read as sRGB (a simulator's or camera's output "
                f"gamma, e.g. 2.2 against 2.4 or the sRGB curve)"), {"gamma": g}
    if tone.family == "generic":
        c, k = math.exp(float(theta[0])), float(theta[1]) ** 2
        white = MID_GREY * (1.0 + k) / k if k > 1e-9 else math.inf
        values = {"contrast": c, "white": white if math.isfinite(white) else 0.0}
        if white < GENERIC_SHOULDER:
            return (f"tone mapping: highlights compressed towards {white:.2f} of white, "
                    f"contrast ×{c:.2f} about mid grey (a view transform or tone curve not "
                    f"among the known ones)"), values
        return (f"tone curve: contrast ×{c:.2f} about mid grey (a tone curve not among the "
                f"known ones)"), values
    owner = "Blender's " if tone.family in ("agx", "filmic", "standard") else "the view "
    if tone.family == "standard":
        curve = tone(np.full((1, 3), 1.0), theta)[0, 1]
        more = "raised" if curve > 1.0 else "lowered"
        return (f"tone curve: contrast {more} about mid grey (a look on the Standard view; "
                f"closest: {owner}'{tone.name}')"), {}
    return (f"tone mapping: highlights compressed (a view transform such as Filmic or AgX; "
            f"closest: {owner}'{tone.name}'; the image is display-referred, not the scene's "
            f"linear values)"), {}


def _causes(problem: _Problem, fit: _Fit, fits: Mapping[_Spec, _Fit],
            base_reference: F64, exposure_counts: bool) -> tuple[Cause, ...]:
    spec = fit.spec
    p = _unpack(spec, fit.theta, problem.expected_ev)
    own = _mean_delta_e(problem, fit)

    def removed(part: str) -> float:
        other = fits.get(spec.without(part))
        if other is None:
            other = problem.fit(spec.without(part))
        return max(0.0, _mean_delta_e(problem, other) - own)

    out = []
    if spec.tone is not None:
        words, values = _tone_words(spec.tone, p["tone"])
        out.append(Cause("tone", words, values, removed("tone"), spec.tone.name))
    if spec.exposure and exposure_counts:
        ev = p["ev"] - problem.expected_ev
        way = "too bright" if ev > 0 else "too dark"
        if spec.tone is not None and spec.tone.family == "generic":
            text = (f"exposure {ev:+z.2f} EV at mid grey ({way}; not separable from a tone "
                    f"curve that is not among the known ones)")
        else:
            text = (f"exposure {ev:+z.2f} EV: every patch ×{2.0 ** ev:.3f}, {way} (a light's "
                    f"strength or units, ambient light from the world or background, or the "
                    f"camera's exposure)")
        out.append(Cause("exposure", text, {"ev": ev}, removed("exposure")))
    if spec.offset:
        b = p["offset"]
        black = int(np.argmin(base_reference @ LUMINANCE))
        y0 = float(base_reference[black] @ LUMINANCE) * 2.0 ** p["ev"]
        what = ("light added to every patch (ambient or veiling light, flare, a lifted black "
                "level)" if b > 0 else "light taken from every patch (crushed blacks, a black "
                "level subtracted)")
        out.append(Cause("black-offset", f"black offset {b:+z.4f} of white: {what}; the black "
                         f"patch {y0:.4f} -> {y0 + b:.4f} linear", {"offset": b},
                         removed("black-offset")))
    if spec.balance:
        r, b = p["gains"]
        out.append(Cause("white-balance", f"white balance: red ×{r:.3f}, blue ×{b:.3f} "
                         f"relative to green (a colour cast: the light's colour or the camera's "
                         f"white balance)", {"red_gain": r, "blue_gain": b},
                         removed("white-balance")))
    if spec.hue:
        h = p["hue"]
        out.append(Cause("hue", f"hue rotated {h:+z.1f}° about the grey axis (linear RGB: a "
                         f"wrong colour matrix or hue setting)", {"hue_degrees": h},
                         removed("hue")))
    if spec.saturation:
        s = p["saturation"]
        out.append(Cause("saturation", f"saturation ×{s:.3f} about the grey axis (linear "
                         f"light: {'more' if s > 1 else 'less'} colour than the reference)",
                         {"saturation": s}, removed("saturation")))
    return tuple(out)


def _gamut_notes(reference: F64, names: Sequence[str] | None) -> tuple[str, ...]:
    out = []
    for k in (int(i) for i in np.flatnonzero(np.any(reference < -1e-6, axis=1))):
        low = int(np.argmin(reference[k]))
        label = f"patch {k + 1}" + (f" ({names[k]})" if names is not None else "")
        out.append(f"{label}: its reference lies outside the sRGB gamut "
                   f"({'RGB'[low]} {reference[k, low]:+z.3f} linear), so a render of sRGB "
                   f"colours clips it: a known limit, not a fault")
    return tuple(out)


def diagnose(measured: ArrayLike, reference: ArrayLike, *, exposure_fixed: bool = True,
             expected_ev: float = 0.0, display_referred: bool = False,
             used: ArrayLike | None = None, patch_names: Sequence[str] | None = None,
             noise_floor: float = NOISE_FLOOR_LAB, applied_ev: float | None = None
             ) -> Diagnosis:
    """The likely cause of a chart's error (module docstring).

    Parameters
    ----------
    measured
        The patches' mean linear sRGB as read (n, 3): scene-linear values of an EXR, or the
        decoded display values of a PNG/JPEG, before any exposure correction; finite.
    reference
        The reference patches in linear sRGB (n, 3), white Y = 1 (negative channels of colours
        outside the gamut are clipped to 0, as a renderer's albedos are).
    exposure_fixed
        True: the image should be at ``expected_ev`` and an exposure error is a cause; False:
        the exposure is normalised (the audit's automatic exposure) and fitted freely.
    expected_ev
        log2 of the expected ratio of measured to reference light (``-EV`` of the audit's
        fixed ``--exposure EV``).
    display_referred
        The image is display-referred (PNG, JPEG: values clipped to [0, 1]); the model clips
        too.
    used
        (n,) which patches to fit (False: a patch left out, covered); None: all.
    patch_names
        The patches' names, for the notes.
    noise_floor
        The smallest noise scale σ of the criterion, CIELAB units per coordinate (> 0).
    applied_ev
        The exposure correction the audit applied (EV), with which the mean ΔE00 values are
        stated as the chart ΔE sees the patches (scaled, sRGB-encoded, clipped to [0, 1]);
        None: ``-expected_ev``.

    Returns
    -------
    Diagnosis
        The causes (each in words, with its values: EV, linear units of white, gain ratios,
        a saturation factor) and the mean ΔE00 before and after; no cause when the base model
        fits within the noise floor.

    Raises
    ------
    InvalidValueError
        Arrays not of shape (n, 3) alike, non-finite values, fewer than 4 patches used, or a
        noise floor <= 0. Exit code 2.
    """
    m = np.asarray(measured, np.float64)
    ref_raw = np.asarray(reference, np.float64)
    if m.ndim != 2 or m.shape[1] != 3 or ref_raw.shape != m.shape:
        raise InvalidValueError(f"measured {m.shape} and reference {ref_raw.shape} patches "
                                "must both be (n, 3)")
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(ref_raw))):
        raise InvalidValueError("the patch means to diagnose must be finite")
    mask = (np.ones(len(m), bool) if used is None else np.asarray(used, bool).reshape(-1))
    if mask.shape != (len(m),) or int(mask.sum()) < 4:
        raise InvalidValueError("a diagnosis needs at least 4 patches")
    if not (noise_floor > 0 and math.isfinite(noise_floor)):
        raise InvalidValueError(f"noise floor {noise_floor!r} must be > 0")
    ref = np.clip(ref_raw, 0.0, None)
    scale = 2.0 ** (-float(expected_ev) if applied_ev is None else float(applied_ev))
    problem = _Problem(ref, _lab(np.clip(m, 0.0, 1.0 if display_referred else None)), mask,
                       float(expected_ev), bool(display_referred), _chart_lab(m, scale), scale)
    notes = _gamut_notes(ref_raw, patch_names)
    counts = bool(exposure_fixed)
    base_spec = _Spec(exposure=not counts)
    base = problem.fit(base_spec, problem.start(base_spec, problem.best_ev(base_spec)[0])
                       if not counts else None)
    base_de = _mean_delta_e(problem, base)
    n = problem.n
    base_ev = _unpack(base_spec, base.theta, problem.expected_ev)["ev"]
    if base.rss / n <= noise_floor ** 2:
        return Diagnosis((), base_de, base_de, 0.0 if counts else base_ev, counts,
                         bool(display_referred), noise_floor, int(mask.sum()), notes, True)
    # screening: exposure and each tone curve alone (a named curve on the exposure grid, a
    # curve with a shape fitted); the best few go on
    screened: list[tuple[float, ToneCurve]] = []
    for tone in tone_curves():
        spec = _Spec(exposure=True, tone=tone)
        ev, rss = problem.best_ev(spec)
        if tone.params:
            rss = problem.fit(spec, problem.start(spec, ev)).rss
        screened.append((rss, tone))
    screened.sort(key=lambda s: s[0])
    tones: list[ToneCurve | None] = [None, *(t for _, t in screened[:TONE_CANDIDATES])]
    fits: dict[_Spec, _Fit] = {base.spec: base}
    deltas: dict[_Spec, float] = {base.spec: base_de}

    def fitted(spec: _Spec, parent: _Fit) -> _Fit:
        if spec not in fits:
            values = dict(_unpack(parent.spec, parent.theta, problem.expected_ev))
            if spec.tone is not None and spec.tone is not parent.spec.tone:
                if parent.spec.tone is None:
                    values["ev"] = problem.best_ev(_Spec(exposure=True, tone=spec.tone))[0]
                values["tone"] = np.zeros(0)
            fits[spec] = problem.fit(spec, _pack(spec, values))
            deltas[spec] = _mean_delta_e(problem, fits[spec])
        return fits[spec]

    # the noise scale: the largest model's residual variance (Mallows), floored
    every = {name: True for name, _, _ in PARTS}
    full = min((fitted(_Spec(**every, tone=t), base) for t in tones), key=lambda f: f.rss)
    sigma2 = max(noise_floor ** 2, full.rss / max(n - full.spec.size, 1))
    penalty = math.log(n)

    def criterion(f: _Fit) -> float:
        return f.rss / sigma2 + penalty * f.spec.penalty(counts)

    # forward selection: add the part (or the tone curve) that lowers the criterion most and
    # removes at least MIN_REMOVED_DELTA_E of the mean ΔE00; stop when none does
    best = base
    while True:
        s0 = best.spec
        steps = [s0.with_part(name) for name, _, _ in PARTS if not getattr(s0, name)]
        if s0.tone is None:
            steps += [replace(s0, tone=t) for t in tones if t is not None]
        options = [f for f in (fitted(spec, best) for spec in steps)
                   if criterion(f) < criterion(best)
                   and deltas[best.spec] - deltas[f.spec] >= MIN_REMOVED_DELTA_E]
        if not options:
            break
        best = min(options, key=criterion)
    ev = _unpack(best.spec, best.theta, problem.expected_ev)["ev"]
    causes = _causes(problem, best, fits, ref, counts)
    share = (base_de - deltas[best.spec]) / base_de if base_de > 0 else 0.0
    if causes and share < MIN_EXPLAINED_SHARE:
        notes = (f"the closest pipeline ({'; '.join(c.text for c in causes)}) explains only "
                 f"{100 * share:.0f} % of the error: not its cause", *notes)
        causes = ()
    return Diagnosis(causes, base_de, deltas[best.spec] if causes else base_de,
                     ev - problem.expected_ev if counts else ev, counts,
                     bool(display_referred), math.sqrt(sigma2), int(mask.sum()), notes)

__all__ = [
    "CAUSES",
    "ENCODING_MISTAKES",
    "GENERIC_CURVE",
    "GENERIC_SHOULDER",
    "LUMINANCE",
    "MID_GREY",
    "MIN_EXPLAINED_SHARE",
    "MIN_REMOVED_DELTA_E",
    "PARTS",
    "NOISE_FLOOR_LAB",
    "TONE_CANDIDATES",
    "VIEW_TRANSFORMS_FILE",
    "Cause",
    "Diagnosis",
    "ToneCurve",
    "diagnose",
    "hue_rotation",
    "least_squares",
    "tone_curves",
    "view_transforms",
]
