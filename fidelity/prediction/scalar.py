"""Scalar root finding and bounded minimisation, without importing SciPy.

``scipy.optimize`` costs 0.5-0.8 s to import on a 2-core machine, more than the rest of a
``fidelity check`` or ``fidelity audit``; the prediction needs only two one-dimensional
solvers, which are short:

- :func:`brent_root`: Brent's method (R. P. Brent, *Algorithms for Minimization without
  Derivatives*, Prentice-Hall 1973, ch. 4, procedure ``zero``), the algorithm and stopping rule
  of ``scipy.optimize.brentq`` (``|x - x*| <= xtol + rtol |x*|``; SciPy's C version:
  ``scipy/optimize/Zeros/brentq.c``).
- :func:`bounded_minimum`: Brent's minimiser on an interval (golden section plus parabolic
  interpolation, Brent 1973 ch. 5, procedure ``localmin``), the algorithm of
  ``scipy.optimize.minimize_scalar(method="bounded")`` (``fminbound``), with its tolerance
  ``xatol``; :func:`bounded_minima` runs several such searches in lockstep, so that their
  function values come from one vectorised call per round.

Both are tested against SciPy's implementations (``tests/prediction/test_scalar.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence

from fidelity.core.errors import InvalidValueError

_EPS = 2.220446049250313e-16  # float64 machine epsilon
#: SciPy's default relative tolerance of brentq: four machine epsilons.
RTOL = 4.0 * _EPS


def brent_root(f: Callable[[float], float], a: float, b: float, *, xtol: float = 2e-12,
               rtol: float = RTOL, maxiter: int = 100) -> float:
    """A root of ``f`` in ``[a, b]``, where ``f(a)`` and ``f(b)`` have opposite signs (or one
    is zero), to within ``xtol + rtol * |x|``.

    Parameters
    ----------
    f
        A continuous function of one float.
    a, b
        The bracket (any order).
    xtol, rtol
        Absolute and relative tolerance on the root (as ``scipy.optimize.brentq``).
    maxiter
        Iterations before giving up.

    Raises
    ------
    InvalidValueError
        ``f(a)`` and ``f(b)`` of the same sign, a non-finite bracket or function value, or no
        convergence in ``maxiter`` iterations.
    """
    search = brent_search(a, b, xtol=xtol, rtol=rtol, maxiter=maxiter)
    x = next(search)
    while True:
        try:
            x = search.send(float(f(x)))
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]


def brent_search(a: float, b: float, *, xtol: float = 2e-12, rtol: float = RTOL,
                 maxiter: int = 100) -> Generator[float, float, float]:
    """:func:`brent_root` as a coroutine: yields each point whose function value it needs
    (``a``, ``b``, then the iterates), is sent the value, returns the root; the same points
    and root, so that a caller can run several searches in lockstep and evaluate their
    functions in one vectorised call per round
    (:func:`fidelity.prediction.calibration.calibrate_transforms`)."""
    if not (math.isfinite(a) and math.isfinite(b)):
        raise InvalidValueError(f"bracket [{a}, {b}] is not finite")
    fa = yield a
    fb = yield b
    if not (math.isfinite(fa) and math.isfinite(fb)):
        raise InvalidValueError(f"f is not finite at the bracket [{a}, {b}]")
    if fa == 0.0:
        return a
    if fb == 0.0:
        return b
    if (fa > 0) == (fb > 0):
        raise InvalidValueError(f"f({a}) = {fa} and f({b}) = {fb} have the same sign")
    # Brent's zero (the variables of brentq.c: xpre/xcur the last two iterates, xblk the
    # contrapoint, spre/scur the previous and current steps)
    xpre, xcur, fpre, fcur = a, b, fa, fb
    xblk, fblk, spre, scur = 0.0, 0.0, 0.0, 0.0
    for _ in range(maxiter):
        if fpre != 0.0 and fcur != 0.0 and (fpre > 0) != (fcur > 0):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):  # the best iterate is kept in xcur
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2.0
        sbis = (xblk - xcur) / 2.0
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            try:
                if xpre == xblk:  # secant
                    stry = -fcur * (xcur - xpre) / (fcur - fpre)
                else:  # inverse quadratic interpolation
                    dpre = (fpre - fcur) / (xpre - xcur)
                    dblk = (fblk - fcur) / (xblk - xcur)
                    stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            except (ZeroDivisionError, OverflowError):  # C gives Inf/NaN here: bisect
                stry = math.inf
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):
                spre, scur = scur, stry  # accept the interpolation
            else:
                spre, scur = sbis, sbis  # bisect
        else:
            spre, scur = sbis, sbis
        xpre, fpre = xcur, fcur
        if abs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = yield xcur
        if not math.isfinite(fcur):
            raise InvalidValueError(f"f is not finite at {xcur}")
    raise InvalidValueError(f"no root found in [{a}, {b}] within {maxiter} iterations")


def bounded_minimum(f: Callable[[float], float], a: float, b: float, *, xatol: float = 1e-5,
                    maxiter: int = 500) -> tuple[float, float]:
    """``(x, f(x))``: a local minimum of ``f`` on ``[a, b]`` (``a < b``), ``x`` to within
    about ``xatol`` (Brent's ``localmin`` as ``scipy.optimize.fminbound``)."""
    search = _localmin(a, b, xatol, maxiter)
    x = next(search)
    while True:
        try:
            x = search.send(float(f(x)))
        except StopIteration as done:
            return done.value  # type: ignore[no-any-return]


def bounded_minima(f: Callable[[list[int], list[float]], Sequence[float]],
                   bounds: Sequence[tuple[float, float]], *, xatol: Sequence[float],
                   maxiter: int = 500) -> list[tuple[float, float]]:
    """:func:`bounded_minimum` of several functions at once, in lockstep: each round asks
    ``f(indices, xs)`` for the values of the functions ``indices`` (into ``bounds``) at
    ``xs``, one point per search still running, so that a caller evaluates them in one
    vectorised call. Every search takes the steps it takes alone: the same ``(x, f(x))``
    as :func:`bounded_minimum` of ``lambda x: f([i], [x])[0]`` on ``bounds[i]``."""
    searches = [_localmin(a, b, t, maxiter) for (a, b), t in zip(bounds, xatol, strict=True)]
    pending = {i: next(s) for i, s in enumerate(searches)}
    found: dict[int, tuple[float, float]] = {}
    while pending:
        order = list(pending)
        values = f(order, [pending[i] for i in order])
        pending = {}
        for i, v in zip(order, values, strict=True):
            try:
                pending[i] = searches[i].send(float(v))
            except StopIteration as done:
                found[i] = done.value
    return [found[i] for i in range(len(searches))]


def _localmin(a: float, b: float, xatol: float, maxiter: int
              ) -> Generator[float, float, tuple[float, float]]:
    """Brent's ``localmin`` as a coroutine: yields each point to evaluate, is sent its value,
    returns ``(x, f(x))``."""
    if not (math.isfinite(a) and math.isfinite(b)) or not a < b:
        raise InvalidValueError(f"bounds [{a}, {b}] must be finite with a < b")
    golden = 0.5 * (3.0 - math.sqrt(5.0))
    sqrt_eps = math.sqrt(_EPS)
    lo, hi = a, b
    x = w = v = lo + golden * (hi - lo)
    fx = fw = fv = yield x
    d = e = 0.0
    for _ in range(maxiter):
        xm = 0.5 * (lo + hi)
        tol1 = sqrt_eps * abs(x) + xatol / 3.0
        tol2 = 2.0 * tol1
        if abs(x - xm) <= tol2 - 0.5 * (hi - lo):
            break
        golden_step = True
        if abs(e) > tol1:  # try a parabola through x, w, v
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r, e = e, d
            if abs(p) < abs(0.5 * q * r) and p > q * (lo - x) and p < q * (hi - x):
                d = p / q
                u = x + d
                if (u - lo) < tol2 or (hi - u) < tol2:
                    d = tol1 if xm >= x else -tol1
                golden_step = False
        if golden_step:
            e = (hi - x) if x < xm else (lo - x)
            d = golden * e
        u = x + (d if abs(d) >= tol1 else (tol1 if d >= 0 else -tol1))
        fu = yield u
        if fu <= fx:
            if u >= x:
                lo = x
            else:
                hi = x
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
        else:
            if u < x:
                lo = u
            else:
                hi = u
            if fu <= fw or w == x:
                v, fv, w, fw = w, fw, u, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
    return x, fx


__all__ = ["RTOL", "bounded_minima", "bounded_minimum", "brent_root", "brent_search"]
