"""Calibration against the paper's statements and an independent colour-science recomputation."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from fidelity.colour.charts import load_chart
from fidelity.core.errors import InvalidValueError, UnreachableTargetError
from fidelity.prediction.calibration import (
    DEFAULT_TARGETS,
    TOLERANCE,
    calibrate_transform,
    calibrate_transforms,
    calibration_table,
    delta_e_curve,
    load_calibration_table,
    transform_delta_e,
)
from fidelity.prediction.transforms import TRANSFORMS

D65_XY = np.array([0.3127, 0.3290])
SRGB = colour.RGB_COLOURSPACES["sRGB"].copy()
SRGB.use_derived_transformation_matrices(True)


@pytest.fixture(scope="module")
def table():  # type: ignore[no-untyped-def]
    return calibration_table()


def _colour_chart_delta_e(rgb: np.ndarray) -> float:
    """Chart ΔE computed with colour-science alone (second method)."""
    chart = load_chart()
    lab = colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, SRGB, apply_cctf_decoding=True), D65_XY)
    return float(np.mean(colour.delta_E(lab, chart.lab, method="CIE 2000")))


def test_default_targets() -> None:
    assert DEFAULT_TARGETS == (*map(float, range(1, 13)), *map(float, range(15, 46, 3)))


def test_baseline_is_the_gamut_clipping_error(table) -> None:  # type: ignore[no-untyped-def]
    # safecolor.md: the untransformed (clipped) chart sits at a mean ΔE00 of about 0.29.
    assert table.baseline_delta_e == pytest.approx(0.29, abs=0.01)
    assert table.baseline_delta_e == pytest.approx(_colour_chart_delta_e(load_chart().srgb), abs=1e-9)


def test_every_reachable_entry_hits_its_target_by_an_independent_recomputation(table) -> None:  # type: ignore[no-untyped-def]
    chart = load_chart()
    assert len(table.entries) == len(TRANSFORMS) * len(DEFAULT_TARGETS)
    for e in table.entries:
        if not e.reachable:
            assert e.param is None
            continue
        assert abs(e.delta_e - e.target) <= TOLERANCE
        lo, hi = sorted(TRANSFORMS[e.transform].param_range)
        assert lo <= e.param <= hi
        out = TRANSFORMS[e.transform](chart.srgb, e.param)
        assert _colour_chart_delta_e(out) == pytest.approx(e.target, abs=TOLERANCE)


# safecolor.md "Known values (4 decimals)"; the paper's search stopped within 0.3 % of the target.
KNOWN = [("contrast-dec", 1.0, 0.9535), ("gamma-inc", 12.0, 1.5509), ("hue", 3.0, 5.3371),
         ("pull_mean", 6.0, 0.7263)]


@pytest.mark.parametrize(("name", "target", "paper"), KNOWN)
def test_known_values_from_the_paper(table, name: str, target: float, paper: float) -> None:  # type: ignore[no-untyped-def]
    # The paper's parameter puts the chart within its stated 0.3 % of the target ...
    reached = float(transform_delta_e(name, paper))
    assert abs(reached - target) <= 0.003 * target
    # ... and ours agrees with it as closely as that tolerance allows.
    ours = table.param(name, target)
    assert ours == pytest.approx(paper, abs=1e-3)


def test_largest_delta_e_is_brightness_dec() -> None:
    # safecolor.md: the largest ΔE any transform reaches on the chart is 47.77 (brightness-dec).
    peaks = {n: max(float(d.max()) for _, d in delta_e_curve(n)) for n in TRANSFORMS}
    assert max(peaks, key=peaks.__getitem__) == "brightness-dec"
    assert peaks["brightness-dec"] == pytest.approx(47.77, abs=0.005)


def test_saturation_inc_plateau(table) -> None:  # type: ignore[no-untyped-def]
    # S clips at 1, so ΔE 9..12 need s from about 5.8 to 35.
    params = [table.param("saturation-inc", t) for t in (9, 10, 11, 12)]
    assert params[0] == pytest.approx(5.8, abs=0.1)
    assert params[-1] == pytest.approx(35.0, abs=0.5)
    assert all(a < b for a, b in zip(params, params[1:], strict=False))
    e = table.entry("saturation-inc", 15.0)
    assert not e.reachable and e.delta_e == pytest.approx(12.74, abs=0.01)


def test_contrast_dec_near_delta_e_24_needs_tiny_c(table) -> None:  # type: ignore[no-untyped-def]
    c = table.param("contrast-dec", 24.0)
    assert 0.0005 < c < 0.002
    # c = 0 gives a uniform mid-grey chart: its ΔE by colour-science alone bounds the reachable range.
    grey = np.full((24, 3), 0.5)
    assert table.entry("contrast-dec", 27.0).delta_e == pytest.approx(_colour_chart_delta_e(grey), abs=1e-6)


def test_gamma_dec_at_its_bound_and_unreachable_beyond(table) -> None:  # type: ignore[no-untyped-def]
    at_bound = float(transform_delta_e("gamma-dec", 0.01))
    assert np.isfinite(at_bound)
    e = table.entry("gamma-dec", 39.0)
    assert not e.reachable and e.delta_e == pytest.approx(at_bound, abs=1e-9)


def test_hue_is_not_monotonic_and_the_smallest_rotation_is_chosen(table) -> None:  # type: ignore[no-untyped-def]
    (pos, d_pos), _ = delta_e_curve("hue")
    assert np.any(np.diff(d_pos) < 0), "hue's ΔE curve should turn back somewhere"
    for target in (3.0, 24.0, 36.0):
        h = table.param("hue", target)
        assert h > 0
        fine = np.linspace(0, h, 4001)[:-1]
        assert np.all(transform_delta_e("hue", fine) < target)  # no smaller rotation reaches it


def test_one_target_solved_alone_equals_the_whole_scan() -> None:
    """calibrate_transform evaluates the scan from the identity only up to the target; the
    table's solver scans every path whole: the same grid, so the very same entries, for
    reachable targets, ones on a grid point, beyond reach, and hue's second path."""
    rng = np.random.default_rng(5)
    targets = [0.05, 0.2905, 1.0, 2.5, 7.0, 13.3, 24.0, 45.0, 80.0,
               *rng.uniform(0.3, 40.0, 12).round(3)]
    whole = calibration_table(targets=targets)
    alone = [calibrate_transform(name, t) for name in TRANSFORMS for t in targets]
    assert list(whole.entries) == alone
    # every transform at once, their searches in lockstep: the same entries again
    together = [calibrate_transforms(list(TRANSFORMS), t) for t in targets]
    assert [row[k] for k in range(len(TRANSFORMS)) for row in together] == alone
    assert any(not e.reachable for e in alone) and any(e.reachable for e in alone)


def test_unreachable_target_strict_raises() -> None:
    with pytest.raises(UnreachableTargetError, match="saturation-inc cannot reach ΔE 30"):
        calibrate_transform("saturation-inc", 30.0, strict=True)
    e = calibrate_transform("saturation-inc", 30.0)
    assert e.param is None and not e.reachable


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_targets_raise(bad: float) -> None:
    with pytest.raises(InvalidValueError, match="target"):
        calibrate_transform("hue", bad)


def test_shipped_table_is_current(table) -> None:  # type: ignore[no-untyped-def]
    # Guards against a stale package-data file: regenerate with the command in reports/calibration.
    shipped = load_calibration_table()
    assert shipped.chart == table.chart
    assert len(shipped.entries) == len(table.entries)
    for a, b in zip(shipped.entries, table.entries, strict=True):
        assert (a.transform, a.target, a.reachable) == (b.transform, b.target, b.reachable)
        if a.param is not None:
            assert a.param == pytest.approx(b.param, rel=1e-9, abs=1e-12)
