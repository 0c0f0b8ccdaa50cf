"""fidelity.prediction.scalar against SciPy's brentq and bounded minimize_scalar (the
algorithms they implement), and the prediction's answers with them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

from fidelity.core.errors import InvalidValueError
from fidelity.prediction.scalar import RTOL, bounded_minima, bounded_minimum, brent_root

ROOTS = [
    (lambda x: x**3 - 2 * x - 5, 2.0, 3.0),                 # Wallis' cubic
    (lambda x: math.cos(x) - x, 0.0, 1.0),
    (lambda x: math.exp(x) - 1e-3, -20.0, 5.0),
    (lambda x: (x - 1.0) ** 9, 0.0, 1.7),                    # flat: a multiple root
    (lambda x: math.atan(x - 1e-9) * 1e-300, -1.0, 1.0),     # denormal-sized values
    (lambda x: x - 1e8, 0.0, 1e9),
    (lambda x: 1.0 if x > 0.3 else -1.0, 0.0, 1.0),          # a jump: bisection to the step
]


@pytest.mark.parametrize("k", range(len(ROOTS)))
def test_brent_root_equals_scipy_brentq(k):
    f, a, b = ROOTS[k]
    ours = brent_root(f, a, b, xtol=1e-14, rtol=RTOL, maxiter=200)
    theirs = brentq(f, a, b, xtol=1e-14, rtol=RTOL, maxiter=200)
    assert ours == pytest.approx(theirs, abs=2e-14 + 8 * RTOL * abs(theirs))


def test_brent_root_endpoints_signs_and_non_finite_values():
    assert brent_root(lambda x: x, 0.0, 1.0) == 0.0
    assert brent_root(lambda x: x - 1.0, 0.0, 1.0) == 1.0
    with pytest.raises(InvalidValueError, match="same sign"):
        brent_root(lambda x: x * x + 1.0, -1.0, 1.0)
    with pytest.raises(InvalidValueError, match="not finite"):
        brent_root(lambda x: math.nan, -1.0, 1.0)
    with pytest.raises(InvalidValueError, match="not finite"):
        brent_root(lambda x: x, -math.inf, 1.0)


MINIMA = [
    (lambda x: (x - 0.3) ** 2, -1.0, 2.0),
    (lambda x: math.cos(x), 2.0, 4.5),
    (lambda x: abs(x - 0.123456789), 0.0, 1.0),              # a kink: golden sections
    (lambda x: x, 0.0, 1.0),                                 # at a bound
    (lambda x: (x - 5.0) ** 4 + 1e-12 * x, 4.0, 7.0),        # flat bottom
]


@pytest.mark.parametrize("k", range(len(MINIMA)))
def test_bounded_minimum_equals_scipy_minimize_scalar(k):
    f, a, b = MINIMA[k]
    xatol = 1e-10 * max(1.0, abs(b - a))
    x, fx = bounded_minimum(f, a, b, xatol=xatol)
    res = minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": xatol})
    assert x == pytest.approx(float(res.x), abs=4 * xatol)
    assert fx == pytest.approx(float(res.fun), abs=1e-15)


def test_bounded_minima_in_lockstep_take_each_search_s_own_steps():
    """Several searches at once give what each gives alone, bit for bit, and every call asks
    only for the searches still running."""
    xatol = [1e-10 * max(1.0, abs(b - a)) for _, a, b in MINIMA]
    asked: list[list[int]] = []

    def batch(ks, xs):
        asked.append(list(ks))
        return [MINIMA[k][0](x) for k, x in zip(ks, xs, strict=True)]

    together = bounded_minima(batch, [(a, b) for _, a, b in MINIMA], xatol=xatol)
    alone = [bounded_minimum(f, a, b, xatol=t) for (f, a, b), t in zip(MINIMA, xatol, strict=True)]
    assert together == alone
    assert asked[0] == list(range(len(MINIMA))) and len(asked[-1]) < len(MINIMA)
    assert all(len(set(ks)) == len(ks) for ks in asked)


def test_bounded_minimum_refuses_empty_bounds():
    with pytest.raises(InvalidValueError):
        bounded_minimum(lambda x: x, 1.0, 1.0)


def test_calibration_and_family_fits_equal_the_scipy_answers():
    """The calibration table and the direction-aware fits computed with these solvers equal
    those computed with SciPy's (to the solvers' tolerances)."""
    from fidelity.colour.charts import load_reference
    from fidelity.prediction import calibration, directional

    def scipy_calibrated(name, target):
        """The parameter nearest the identity reaching ``target``: the first bracket of the
        transform's scanned ΔE curve, solved by SciPy's brentq."""
        for params, des in calibration.delta_e_curve(name):
            first = calibration._first_crossing(des, target)
            if first is None:
                continue
            i, on_grid = first

            def f(x):
                return float(calibration.transform_delta_e(name, x)) - target

            a, b = sorted((float(params[i]), float(params[min(i + 1, len(params) - 1)])))
            x = float(params[i]) if on_grid else float(
                brentq(f, a, b, xtol=1e-14, rtol=RTOL, maxiter=200))
            if abs(f(x)) <= calibration.TOLERANCE:
                return x
        return None

    def scipy_minima(f, bounds, xatol):
        out = []
        for i, ((a, b), t) in enumerate(zip(bounds, xatol, strict=True)):
            r = minimize_scalar(lambda x, i=i: f([i], [x])[0], bounds=(a, b), method="bounded",
                                options={"xatol": t})
            out.append((float(r.x), float(r.fun)))
        return out

    names = ("hue", "gamma-inc", "saturation-dec", "contrast-inc")
    for target in (1.0, 3.0, 12.0):
        together = calibration.calibrate_transforms(names, target)
        for name, ours in zip(names, together, strict=True):
            assert ours == calibration.calibrate_transform(name, target)  # lockstep: the same
            theirs = scipy_calibrated(name, target)
            assert ours.reachable == (theirs is not None)
            if ours.reachable:
                assert ours.param == pytest.approx(theirs, rel=1e-12, abs=1e-13)
    ref = np.asarray(load_reference("scene", "D65").lab)
    lab = ref + np.array([1.5, -2.0, 3.0])
    for fit in ("gamma", "hue", "saturation"):
        ours = directional.fit_family(ref, lab, fit)
        orig = directional.bounded_minima
        directional.bounded_minima = scipy_minima
        try:
            theirs = directional.fit_family(ref, lab, fit)
        finally:
            directional.bounded_minima = orig
        assert ours.param == pytest.approx(theirs.param, rel=1e-9, abs=1e-12)
