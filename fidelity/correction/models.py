"""Colour-correction models fitted from one chart's colours to another's.

Every model maps linear RGB ``(..., 3)`` (the *fit space*: linear sRGB, Rec. 709 primaries, D65,
the perfect white at 1) of the simulated chart onto the real camera's; the model families of
:data:`MODELS` (the registry) are nested, from the fewest coefficients to the most:

``gains``
    Per-channel gains (3 coefficients): a white-balance and exposure difference, von Kries's
    diagonal model.
``matrix``
    A 3 x 3 matrix (9): any linear difference of primaries, white balance and exposure; the
    colour-correction matrix of a camera pipeline (Cheung et al. 2004, linear terms).
``matrix+curve``
    A tone curve shared by the three channels, then a 3 x 3 matrix (9 + 4): the curve is a
    monotone piecewise-cubic (PCHIP, Fritsch and Carlson 1980) map ``phi`` of the sRGB-encoded
    value with ``phi(0) = 0``, ``phi(1) = 1`` and free values at the encoded levels
    :data:`CURVE_KNOTS` (a difference of tone curve, e.g. a gamma 2.2 encoding read as sRGB),
    applied as ``decode(phi(encode(v)))``.
``root-polynomial``
    Finlayson, Mackiewicz and Hurlbert's root-polynomial colour correction of degree 2 (IEEE
    TIP 24(5), 2015): terms ``r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)`` and a 3 x 6 matrix (18).
    Every term scales with exposure, so the correction does not change with the exposure, as a
    plain polynomial would.

Fitting (:func:`fit_model`) minimises, over the patches used, either

- ``linear``: the weighted squared difference in linear RGB, in closed form
  (weighted least squares; the curve by variable projection, Golub and Pereyra 1973: for each
  curve the best matrix in closed form, the curve by :func:`scipy.optimize.least_squares`), or
- ``ciede2000``: the weighted sum of squared CIEDE2000 differences (Sharma, Wu, Dalal 2005) of
  the corrected colours against the real ones (the quantity the reports show), by
  :func:`scipy.optimize.least_squares` (Levenberg-Marquardt) started from the ``linear``
  solution (or from ``start``),

and :data:`DEFAULT_OBJECTIVE` is the one that gave the lower cross-validated ΔE00 on the
suite's cameras (``docs/fit.md``). Conditioning (:class:`Conditioning`): the design matrix's
condition number above :data:`CONDITION_LIMIT` (a chart whose colours span too little of RGB:
nearly grey, or patches lost to clipping) regularises the fit towards the identity (Tikhonov,
with the smallest weight that brings the condition number to the limit) and says so; fewer
patches than coefficients + 2, or coefficients beyond :data:`MAX_COEFFICIENT` even so, are
refused (:class:`~fidelity.core.errors.InvalidValueError`). :func:`cross_validate` predicts each
patch from a fit that did not see it (leave-k-patches-out, rotating through the chart).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour.colorimetry import (
    delinearize_srgb,
    delta_e_2000,
    linear_srgb_to_xyz,
    linearize_srgb,
    xyz_to_lab,
)
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Encoded (sRGB) levels of the tone curve's free values (``matrix+curve``); 0 and 1 are fixed.
CURVE_KNOTS: tuple[float, ...] = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
#: The fitting objectives (module docstring).
OBJECTIVES: tuple[str, ...] = ("linear", "ciede2000")
#: Condition number of the weighted design matrix above which the fit is regularised. The
#: Macbeth chart under D65 through an exact camera gives about 8 (matrix) and 60
#: (root-polynomial); a limit of 1000 leaves every honest chart alone.
CONDITION_LIMIT = 1000.0
#: Largest coefficient magnitude a fit may return; larger is refused as unstable.
MAX_COEFFICIENT = 20.0


def expand_linear(rgb: F64) -> F64:
    """The terms of ``gains`` and ``matrix``: ``r, g, b`` themselves, ``(..., 3)``."""
    return rgb


def expand_root_polynomial(rgb: F64) -> F64:
    """Finlayson et al. 2015's root-polynomial terms of degree 2, ``(..., 3) -> (..., 6)``:
    ``r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)``; a product below 0 (a negative channel of an
    out-of-gamut colour) gives 0."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    roots = [np.sqrt(np.maximum(p, 0.0)) for p in (r * g, g * b, r * b)]
    return np.concatenate([rgb, np.stack(roots, axis=-1)], axis=-1)


@record
class ModelFamily:
    """A registered model: its terms, whether the matrix is diagonal, whether a tone curve
    comes first, and the coefficients of the identity."""

    name: str
    expand: Callable[[F64], F64]
    terms: int
    diagonal: bool = False
    curve: bool = False

    @property
    def identity(self) -> F64:
        """``(terms, 3)`` coefficients of the identity map."""
        m = np.zeros((self.terms, 3))
        m[:3, :3] = np.eye(3)
        return m

    @property
    def parameters(self) -> int:
        """How many numbers the fit chooses."""
        return (3 if self.diagonal else 3 * self.terms) + (len(CURVE_KNOTS) - 2
                                                           if self.curve else 0)


#: The model registry (module docstring).
MODELS: dict[str, ModelFamily] = {
    "gains": ModelFamily("gains", expand_linear, 3, diagonal=True),
    "matrix": ModelFamily("matrix", expand_linear, 3),
    "matrix+curve": ModelFamily("matrix+curve", expand_linear, 3, curve=True),
    "root-polynomial": ModelFamily("root-polynomial", expand_root_polynomial, 6),
}


def model_family(name: str) -> ModelFamily:
    """The registered :class:`ModelFamily` called ``name``."""
    if name not in MODELS:
        raise unknown_name("correction model", name, MODELS)
    return MODELS[name]


def tone_curve(values: F64, curve: F64) -> F64:
    """Apply the shared tone curve ``decode(phi(encode(v)))`` to linear values.

    ``curve`` is ``phi`` at :data:`CURVE_KNOTS` (increasing, 0 and 1 at the ends); ``phi`` is
    the PCHIP interpolant, continued beyond 1 by its tangent at 1 and odd below 0."""
    from scipy.interpolate import PchipInterpolator

    knots = np.asarray(CURVE_KNOTS)
    phi = PchipInterpolator(knots, curve, extrapolate=False)
    slope = float(phi.derivative()(1.0))
    enc = np.asarray(delinearize_srgb(np.abs(values)), np.float64)
    inside = np.minimum(enc, 1.0)
    out = np.where(enc > 1.0, 1.0 + slope * (enc - 1.0), phi(inside))
    return np.sign(values) * np.asarray(linearize_srgb(out), np.float64)


@record
class ColourModel:
    """A fitted correction in the fit space (module docstring).

    ``coefficients``: ``(terms, 3)``, ``corrected = terms(curve(rgb)) @ coefficients``;
    ``curve``: ``phi`` at :data:`CURVE_KNOTS` (``matrix+curve``), else None."""

    name: str
    coefficients: F64
    curve: F64 | None = None

    @property
    def family(self) -> ModelFamily:
        """The model's :class:`ModelFamily`."""
        return model_family(self.name)

    def terms(self, rgb: ArrayLike) -> F64:
        """The model's terms of linear RGB ``(..., 3) -> (..., terms)`` (after the curve)."""
        a = np.asarray(rgb, np.float64)
        if self.curve is not None:
            a = tone_curve(a, self.curve)
        return self.family.expand(a)

    def apply(self, rgb: ArrayLike) -> F64:
        """Corrected linear RGB of linear RGB ``(..., 3)``."""
        return self.terms(rgb) @ self.coefficients

    @property
    def matrix(self) -> F64:
        """The 3 x 3 part of the coefficients as ``out = M @ in`` (rows: output channels)."""
        return np.asarray(self.coefficients[:3, :3].T, np.float64)

    @property
    def gains(self) -> tuple[float, float, float]:
        """The white-balance gains the matrix carries: its row sums (what it does to grey)."""
        s = self.matrix.sum(axis=1)
        return (float(s[0]), float(s[1]), float(s[2]))

    def to_json(self) -> dict[str, Any]:
        """``model``, ``matrix`` (3 x 3, rows = output R, G, B), ``coefficients`` (terms x 3 as
        rows = output channels), ``gains`` and the ``curve`` (``knots``, ``values``)."""
        return {"model": self.name, "matrix": self.matrix.tolist(),
                "coefficients": self.coefficients.T.tolist(), "gains": list(self.gains),
                "curve": None if self.curve is None else {
                    "knots_encoded": list(CURVE_KNOTS), "values_encoded": self.curve.tolist()}}


@record
class Conditioning:
    """How well the chart determines the fit: the weighted design's ``condition_number``, the
    ``limit`` it is held to, the Tikhonov weight ``ridge`` used (0: none) and the ``reason``
    in words when regularised."""

    condition_number: float
    limit: float
    ridge: float = 0.0
    reason: str | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON form."""
        return {"condition_number": self.condition_number, "limit": self.limit,
                "ridge": self.ridge, "reason": self.reason}


def linear_to_lab(rgb: F64) -> F64:
    """CIELAB (D65) of linear sRGB ``(..., 3)``, negatives clipped to 0 first (a stored image
    cannot hold them)."""
    return np.asarray(xyz_to_lab(linear_srgb_to_xyz(np.maximum(rgb, 0.0))), np.float64)


def patch_delta_e(predicted: F64, target: F64) -> F64:
    """CIEDE2000 per patch of two linear sRGB colour sets ``(n, 3)``."""
    return np.asarray(delta_e_2000(linear_to_lab(predicted), linear_to_lab(target)), np.float64)


def _check(sim: ArrayLike, real: ArrayLike, weights: ArrayLike | None
           ) -> tuple[F64, F64, F64]:
    x = np.asarray(sim, np.float64)
    y = np.asarray(real, np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape != y.shape:
        raise InvalidValueError(f"sim and real patch colours must both be (n, 3), got "
                                f"{x.shape} and {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise InvalidValueError("the patch colours have NaN or Inf values")
    w = np.ones(len(x)) if weights is None else np.asarray(weights, np.float64)
    if w.shape != (len(x),) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InvalidValueError(f"weights must be {len(x)} finite numbers >= 0")
    return x, y, w


def _ridge_for(singular: F64, limit: float) -> tuple[float, float]:
    """The condition number of singular values and the smallest Tikhonov weight that brings
    the condition number of the normal equations to ``limit**2``."""
    smax, smin = float(singular.max()), float(singular.min())
    cond = math.inf if smin <= smax * 1e-15 else smax / smin
    if cond <= limit:
        return cond, 0.0
    return cond, (smax ** 2 - limit ** 2 * smin ** 2) / (limit ** 2 - 1.0)


def _solve(family: ModelFamily, terms: F64, y: F64, w: F64, ridge: float) -> F64:
    """Weighted (ridge-regularised towards the identity) least squares for the coefficients."""
    m0 = family.identity
    if family.diagonal:
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            g = ((w[:, None] * terms * y).sum(axis=0) + ridge) / (
                (w[:, None] * terms ** 2).sum(axis=0) + ridge)
        return np.diag(np.where(np.isnan(g), np.inf, g))
    a = terms.T @ (w[:, None] * terms) + ridge * np.eye(family.terms)
    b = terms.T @ (w[:, None] * y) + ridge * m0
    return np.asarray(np.linalg.solve(a, b), np.float64)


def _curve_from(theta: F64) -> F64:
    """Monotone curve values at :data:`CURVE_KNOTS` from free parameters: the increments are
    ``exp`` of ``(0, theta)`` normalised to sum 1 (all equal: the identity)."""
    d = np.exp(np.concatenate([[0.0], theta]))
    return np.concatenate([[0.0], np.cumsum(d) / d.sum()])


def _design(family: ModelFamily, x: F64, w: F64) -> tuple[float, float, str | None]:
    terms = family.expand(x)
    sw = np.sqrt(w)[:, None] * terms
    if family.diagonal:
        norms = np.sqrt((sw ** 2).sum(axis=0))
        singular = norms
    else:
        singular = np.linalg.svd(sw, compute_uv=False)
    cond, ridge = _ridge_for(singular, CONDITION_LIMIT)
    reason = None
    if ridge > 0:
        reason = (f"the simulated chart's colours span too little of RGB to determine the "
                  f"{family.name} model (condition number {cond:.3g} > {CONDITION_LIMIT:g}): "
                  f"regularised towards the identity (Tikhonov weight {ridge:.3g})")
    return cond, ridge, reason


def fit_model(sim: ArrayLike, real: ArrayLike, model: str = "matrix", *,
              weights: ArrayLike | None = None, objective: str | None = None,
              start: ColourModel | None = None) -> tuple[ColourModel, Conditioning]:
    """Fit ``model`` (:data:`MODELS`) mapping the ``sim`` patch colours onto the ``real`` ones.

    Parameters
    ----------
    sim, real
        ``(n, 3)`` linear sRGB of the patches used (fit space, module docstring).
    model
        The model family: ``gains``, ``matrix`` (default), ``matrix+curve`` or
        ``root-polynomial`` (:data:`MODELS`).
    weights
        ``(n,)`` non-negative weights of the patches (default 1).
    objective
        ``linear`` or ``ciede2000`` (:data:`OBJECTIVES`); None: :data:`DEFAULT_OBJECTIVE`.
    start
        Where the ``ciede2000`` search starts (a fit of the same model); None: the ``linear``
        solution.

    Returns
    -------
    The fitted :class:`ColourModel` and its :class:`Conditioning`. Raises
    :class:`~fidelity.core.errors.InvalidValueError` for too few patches or an unstable fit.
    """
    family = model_family(model)
    objective = DEFAULT_OBJECTIVE if objective is None else objective
    if objective not in OBJECTIVES:
        raise unknown_name("fitting objective", objective, OBJECTIVES)
    x, y, w = _check(sim, real, weights)
    used = int(np.count_nonzero(w > 0))
    need = family.parameters // 3 + 2
    if used < need:
        raise InvalidValueError(f"{used} usable patches cannot determine the {model} model: it "
                                f"needs at least {need}")
    if not np.any(np.abs(x[w > 0]) > 0):
        raise InvalidValueError("the simulated chart's patches are all black: nothing to fit")
    cond, ridge, reason = _design(family, x, w)
    conditioning = Conditioning(cond, CONDITION_LIMIT, ridge, reason)
    if objective == "ciede2000" and start is not None and start.name == model:
        fitted = start
    elif family.curve:
        from scipy.optimize import least_squares

        def coefficients(theta: F64) -> tuple[F64, F64]:
            curve = _curve_from(theta)
            return _solve(family, family.expand(tone_curve(x, curve)), y, w, ridge), curve

        def residual(theta: F64) -> F64:
            coef, curve = coefficients(theta)
            pred = family.expand(tone_curve(x, curve)) @ coef
            return np.asarray((np.sqrt(w)[:, None] * (pred - y)).ravel(), np.float64)

        sol = least_squares(residual, np.zeros(len(CURVE_KNOTS) - 2), method="lm")
        coef, curve = coefficients(np.clip(sol.x, -30, 30))
        fitted = ColourModel(model, coef, curve)
    else:
        fitted = ColourModel(model, _solve(family, family.expand(x), y, w, ridge))
    if objective == "ciede2000":
        fitted = _fit_ciede2000(family, fitted, x, y, w, ridge)
    biggest = float(np.max(np.abs(fitted.coefficients)))
    if not biggest <= MAX_COEFFICIENT:
        raise InvalidValueError(
            f"the {model} fit is unstable: a coefficient of {biggest:.3g} (more than "
            f"{MAX_COEFFICIENT:g}) would amplify noise; the simulated chart's colours do not "
            f"determine the model (condition number {cond:.3g}); try a model with fewer "
            f"coefficients")
    return fitted, conditioning


#: Scale of the Tikhonov term of the ``ciede2000`` objective against the one of ``linear``: a
#: linear-RGB difference of 1 is about 100 units of CIELAB.
CIEDE2000_RIDGE_SCALE = 100.0
#: Relative tolerance of the ``ciede2000`` fit (ΔE00 changes below 1e-4 of it stop it).
CIEDE2000_TOLERANCE = 1e-4
#: Most evaluations of the ``ciede2000`` fit's residual per parameter.
CIEDE2000_EVALUATIONS = 40


def _fit_ciede2000(family: ModelFamily, start: ColourModel, x: F64, y: F64, w: F64,
                ridge: float) -> ColourModel:
    from scipy.optimize import least_squares

    target = linear_to_lab(y)
    m0 = family.identity
    k = len(CURVE_KNOTS) - 2 if family.curve else 0
    diag = family.diagonal

    def unpack(p: F64) -> ColourModel:
        coef = np.diag(p[:3]) if diag else p[:3 * family.terms].reshape(family.terms, 3)
        curve = _curve_from(p[-k:]) if k else None
        return ColourModel(family.name, coef, curve)

    def residual(p: F64) -> F64:
        m = unpack(p)
        de = delta_e_2000(linear_to_lab(m.apply(x)), target)
        out = [np.sqrt(w) * de]
        if ridge > 0:
            out.append(math.sqrt(ridge) * CIEDE2000_RIDGE_SCALE * (m.coefficients - m0).ravel())
        return np.concatenate(out)

    p0 = [np.diag(start.coefficients) if diag else start.coefficients.ravel()]
    if k:
        assert start.curve is not None
        inc = np.maximum(np.diff(start.curve), 1e-9)
        p0.append(np.log(inc[1:] / inc[0]))
    start_p = np.concatenate(p0)
    sol = least_squares(residual, start_p, method="lm", ftol=CIEDE2000_TOLERANCE,
                        xtol=CIEDE2000_TOLERANCE, max_nfev=CIEDE2000_EVALUATIONS * (len(start_p) + 1))
    return unpack(np.asarray(sol.x, np.float64))


#: Patches held out together in :func:`cross_validate`.
HOLD_OUT = 3


def cross_validate(sim: ArrayLike, real: ArrayLike, model: str = "matrix", *,
                   weights: ArrayLike | None = None, objective: str | None = None,
                   hold_out: int = HOLD_OUT, start: ColourModel | None = None) -> F64:
    """Cross-validated ΔE00 of each patch: leave ``hold_out`` patches out at a time, rotating
    through the chart (fold ``j`` holds out the used patches ``j, j + F, j + 2F, ...`` with
    ``F = ceil(used / hold_out)`` folds, so that each fold takes patches from all over the
    chart), fit on the others (:func:`fit_model`, with the same objective and regularisation
    rule) and measure the held-out patches' CIEDE2000 against the real ones.

    ``start``: where each fold's ``ciede2000`` search starts (the fit on all patches; the
    held-out patches still do not enter the fold's objective).

    Returns ``(n,)``: each used patch's held-out ΔE00; NaN for patches of weight 0.
    """
    x, y, w = _check(sim, real, weights)
    used = np.flatnonzero(w > 0)
    folds = max(2, math.ceil(len(used) / max(1, hold_out)))
    out = np.full(len(x), np.nan)
    for j in range(folds):
        held = used[j::folds]
        if held.size == 0:
            continue
        wj = w.copy()
        wj[held] = 0.0
        fitted, _ = fit_model(x, y, model, weights=wj, objective=objective, start=start)
        out[held] = patch_delta_e(fitted.apply(x[held]), y[held])
    return out


#: The objective :func:`fit_model` uses by default: the one with the lower cross-validated
#: ΔE00 on the suite's cameras (measured by ``benchmarks/speed/fit.py``, ``docs/fit.md``).
DEFAULT_OBJECTIVE = "ciede2000"


def usable_patches(sim_srgb: ArrayLike, real_srgb: ArrayLike, names: Sequence[str],
                   sim_clipped: Sequence[str] = (), real_clipped: Sequence[str] = (), *,
                   high: float = 0.99, low: float = 0.0,
                   sim_float: bool = False) -> dict[str, str]:
    """Patches to exclude from a fit, by name, with the reason: clipped by either chart's
    audit (``sim_clipped``, ``real_clipped``: out of the encoded range), or a channel of either
    chart's encoded sRGB ``(n, 3)`` at or beyond ``high`` (saturated) or at or below ``low``
    (crushed to black). ``sim_float``: the simulated chart is a floating-point scene-linear
    render, whose values above 1 are light, not clipping (only ``low`` applies to it)."""
    s = np.asarray(sim_srgb, np.float64)
    r = np.asarray(real_srgb, np.float64)
    out: dict[str, str] = {}
    for k, name in enumerate(names):
        for who, v, clipped in (("simulated", s[k], sim_clipped), ("real", r[k], real_clipped)):
            top = np.inf if sim_float and who == "simulated" else high
            if name in clipped:
                out[name] = f"clipped in the {who} chart (outside the encoded range)"
            elif np.any(v >= top):
                out[name] = f"saturated in the {who} chart (a channel >= {high:g})"
            elif np.any(v <= low):
                out[name] = f"crushed to black in the {who} chart (a channel <= {low:g})"
            else:
                continue
            break
    return out


#: Alternating least-squares rounds of :func:`fit_shared_matrix` at most, and the relative
#: change of the coefficients below which it stops.
SHARED_ROUNDS, SHARED_TOLERANCE = 200, 1e-12


def _gains_for(matrix: F64, x: F64, y: F64, w: F64) -> F64:
    """The per-channel gains ``g`` minimising ``sum w |y - M (g * x)|^2`` (closed form)."""
    a = (x[:, None, :] * matrix[None, :, :]).reshape(-1, 3)  # rows: M[c] * x[k]
    sw = np.repeat(np.sqrt(w), 3)
    g, *_ = np.linalg.lstsq(a * sw[:, None], y.reshape(-1) * sw, rcond=None)
    return np.asarray(g, np.float64)


def fit_shared_matrix(sims: Sequence[ArrayLike], reals: Sequence[ArrayLike], *,
                      weights: Sequence[ArrayLike | None] | None = None
                      ) -> tuple[ColourModel, tuple[F64, ...], Conditioning]:
    """One matrix ``M`` and per-chart gains ``g_i`` with ``real_i = M (g_i * sim_i)`` over
    several pairs of charts (the same camera under several illuminants: the white balance
    changes with the illuminant, the colour matrix does not), by weighted least squares in
    linear RGB (alternating: the matrix in closed form with :func:`fit_model`'s conditioning
    rule over all pairs, then each pair's gains in closed form, until the coefficients change
    by less than :data:`SHARED_TOLERANCE`). ``M`` and the gains are determined up to a
    per-channel scale; the first pair's gains are fixed at 1 (the matrix carries its white
    balance; the others' gains are relative to it).

    Returns the matrix as a ``matrix`` :class:`ColourModel`, the gains ``(3,)`` per pair and
    the matrix step's :class:`Conditioning`. Gains beyond :data:`MAX_COEFFICIENT` or not
    positive are refused (:class:`~fidelity.core.errors.InvalidValueError`)."""
    if len(sims) != len(reals) or not sims:
        raise InvalidValueError("fit_shared_matrix needs as many sim charts as real ones, "
                                "at least one")
    ws = list(weights) if weights is not None else [None] * len(sims)
    data = [_check(s, r, w) for s, r, w in zip(sims, reals, ws, strict=True)]
    gains = [np.ones(3) for _ in data]
    model, cond = fit_model(np.concatenate([x for x, _, _ in data]),
                            np.concatenate([y for _, y, _ in data]), "matrix",
                            weights=np.concatenate([w for _, _, w in data]), objective="linear")
    for _ in range(SHARED_ROUNDS):
        m = model.matrix
        new = [np.ones(3)] + [_gains_for(m, x, y, w) for x, y, w in data[1:]]
        for i, g in enumerate(new):
            if not (np.all(np.isfinite(g)) and np.all(g > 0) and np.all(g <= MAX_COEFFICIENT)):
                raise InvalidValueError(
                    f"the gains of pair {i + 1} ({', '.join(f'{v:.3g}' for v in g)}) are not "
                    f"positive numbers up to {MAX_COEFFICIENT:g}: the charts do not share a "
                    "colour matrix")
        model, cond = fit_model(np.concatenate([x * g for (x, _, _), g in zip(data, new,
                                                                              strict=True)]),
                                np.concatenate([y for _, y, _ in data]), "matrix",
                                weights=np.concatenate([w for _, _, w in data]),
                                objective="linear")
        change = max(float(np.max(np.abs(model.matrix - m))),
                     max(float(np.max(np.abs(a - b))) for a, b in zip(new, gains, strict=True)))
        gains = new
        if change < SHARED_TOLERANCE:
            break
    return model, tuple(gains), cond


def cross_validate_shared(sims: Sequence[ArrayLike], reals: Sequence[ArrayLike], *,
                          weights: Sequence[ArrayLike | None] | None = None,
                          hold_out: int = HOLD_OUT) -> tuple[F64, ...]:
    """:func:`cross_validate` of :func:`fit_shared_matrix`: fold ``j`` holds the same patches
    out of every pair (the used patches of the first pair ``j, j + F, ...``), so that a patch
    is predicted under every illuminant by a fit that saw it under none. Returns ``(n,)`` per
    pair, NaN for patches of weight 0."""
    ws = list(weights) if weights is not None else [None] * len(sims)
    data = [_check(s, r, w) for s, r, w in zip(sims, reals, ws, strict=True)]
    used = np.flatnonzero(np.any([w > 0 for _, _, w in data], axis=0))
    folds = max(2, math.ceil(len(used) / max(1, hold_out)))
    out = [np.full(len(x), np.nan) for x, _, _ in data]
    for j in range(folds):
        held = used[j::folds]
        if held.size == 0:
            continue
        wj = []
        for _, _, w in data:
            w = w.copy()
            w[held] = 0.0
            wj.append(w)
        model, gains, _ = fit_shared_matrix([x for x, _, _ in data], [y for _, y, _ in data],
                                            weights=wj)
        for i, ((x, y, w), g) in enumerate(zip(data, gains, strict=True)):
            keep = held[w[held] > 0]
            out[i][keep] = patch_delta_e(model.apply(x[keep] * g), y[keep])
    return tuple(out)


__all__ = [
    "CONDITION_LIMIT",
    "SHARED_ROUNDS",
    "SHARED_TOLERANCE",
    "cross_validate_shared",
    "fit_shared_matrix",
    "CURVE_KNOTS",
    "ColourModel",
    "Conditioning",
    "DEFAULT_OBJECTIVE",
    "HOLD_OUT",
    "MAX_COEFFICIENT",
    "MODELS",
    "ModelFamily",
    "OBJECTIVES",
    "cross_validate",
    "expand_linear",
    "expand_root_polynomial",
    "fit_model",
    "linear_to_lab",
    "model_family",
    "patch_delta_e",
    "tone_curve",
    "usable_patches",
]
