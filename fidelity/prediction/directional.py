"""Direction-aware prediction: which way a chart is wrong decides what its error costs.

The classic prediction (:func:`fidelity.prediction.table.predict`) charges every chart error
the worst loss of *any* SAFE-COLOR transform at that chart ΔE, and above ΔE 4 the worst is a
contrast change, which real cameras seldom make; so it over-predicts realistic cameras by an
order of magnitude (``reports/validation``). This module charges each part of a chart's error
the worst loss of the transforms that move the chart *that way*.

**The parts of a chart error** (:func:`error_parts`). CIEDE2000 (Sharma, Wu & Dalal 2005)
adds three weighted terms per patch, lightness ``l = ΔL'/S_L``, chroma ``c = ΔC'/S_C`` and
hue ``h = ΔH'/S_H``: ``ΔE00² = l² + c² + h² + R_T c h``. Each patch's ΔE00 is split into
three non-negative parts in proportion to ``l²``, ``c²`` and ``h²`` (the rotation term goes
with them pro rata), so that the chart's mean ΔE00 is exactly ``lightness + chroma + hue``.

**Transform families** (:data:`FAMILIES`), from the sweep's ten transforms, and what they move
on the calibration chart (mean share of the chart ΔE over ΔE 1-24, :func:`family_shares`):

==============  ======================================  ======================================
family          transforms                              moves (lightness / chroma / hue)
==============  ======================================  ======================================
``tone``        brightness-dec/-inc, gamma-dec/-inc      lightness: 82-91 % / 4-8 % / 5-13 %
``chroma``      saturation-dec/-inc                      36-39 % / 46-56 % / 5-18 %
``hue``         hue                                      12 % / 5 % / 83 %
``contrast``    contrast-dec/-inc                        44-47 % / 32-52 % / 4-21 %
``pull_mean``   pull_mean                                37 % / 46 % / 17 %
==============  ======================================  ======================================

Each family has a worst-case curve per detector size (and model): at each ΔE the largest loss
of its transforms (and models), from the sweep's cells
(:func:`fidelity.coco.tables.directional.directional_table`, written to
``fidelity/data/prediction/coco1000-directional.json``).

**What explains a chart** (:func:`fit_families`). Each one-parameter family of the transforms
(``brightness``, ``gamma``, ``contrast``, ``saturation``, ``hue``, ``pull_mean``; both
directions) is fitted to the chart: the parameter that brings the transformed reference chart
closest to the measured one (least mean ΔE00; a scan of the parameter range, then Brent's
bounded method). The family that removes the largest share ``x`` of the chart's error
(``x = 1 - residual / error``, in [0, 1]) *explains* that share, when it removes at least
:data:`MIN_EXPLAINED` of it and :data:`MIN_EXPLAINED_DELTA_E` of mean ΔE00. These fits
decide the prediction's weights; the likely *cause* of a chart error in words is
:mod:`fidelity.colour.diagnosis`'s.

**The prediction** (:func:`predict_directional`) at the chart's ΔE ``E`` is a weighted sum of
family curves, each read at ``E``::

    loss = x · f_F(E) + (1 - x) · [s_L · f_tone(E) + s_C · f_chroma(E) + s_H · f_hue(E)]

with ``F`` the family of the best fit, and ``s_L, s_C, s_H`` the lightness, chroma and hue
shares of what the fit leaves (the residual chart error). A chart that *is* a SAFE-COLOR
transform is explained fully (``x = 1``) and gets that transform family's worst case, so the
sweep's own cells stay bounded; an error no family explains (a white-balance cast) is charged
by its direction. Every weight is at most 1 and the weights add up to 1, so the prediction
never exceeds the classic one (the worst over all transforms). Beyond the ΔE range a family was
measured on (``chroma`` ends at ΔE 21, as the saturation transforms reach no further on the
chart) its part is charged the classic curve: no extrapolation.

Like the classic measured table, it is an empirical worst case, not a guarantee; the
validation on 30 realistic camera models (``reports/validation``) checks it against the loss
measured by emulating each camera on COCO.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour.charts import DEFAULT_CHART, load_chart
from fidelity.colour.colorimetry import delta_e_2000, lab_to_srgb, srgb_to_lab
from fidelity.core.errors import InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import cached_while_unchanged
from fidelity.core.record import record
from fidelity.prediction import transforms as tr
from fidelity.prediction.calibration import load_calibration_table
from fidelity.prediction.interpolate import predict_curve
from fidelity.prediction.scalar import bounded_minima
from fidelity.prediction.table import predict
from fidelity.prediction.tablefile import (
    CLASS_COLUMNS,
    TableKind,
    load_prediction_table,
    parse_prediction_table,
)
from fidelity.prediction.transforms import TRANSFORMS
from fidelity.prediction.verdict import SIMPLE, evaluate, judge_value

if TYPE_CHECKING:
    from pathlib import Path

    from fidelity.measure.colour import ChartMeasurement
    from fidelity.prediction.tablefile import PredictionTable
    from fidelity.prediction.verdict import Criterion, DecisionRule, Verdict

F64 = NDArray[np.float64]

#: The direction-aware table used when none is named.
DEFAULT_DIRECTIONAL_TABLE = "coco1000-directional"
#: The three directions of a CIEDE2000 difference.
DIRECTIONS: tuple[str, ...] = ("lightness", "chroma", "hue")
#: Which bound decides a verdict: the classic worst case (default) or the direction-aware one.
BOUNDS: tuple[str, ...] = ("classic", "directional")
#: Loss columns (as in :data:`fidelity.prediction.tablefile.COLUMNS`).
COLUMNS: tuple[str, ...] = ("dmap_points", "dmap_relative", "dap_person_points",
                            "dap_bicycle_points")
#: Share of the chart error a fit must remove to count as an explanation (below: noise).
MIN_EXPLAINED = 0.02
#: Least mean ΔE00 a fit must remove to count as an explanation: below it, a parameter at its
#: identity can still "explain" a share of a tiny error (the ΔE00 is not smooth at the sRGB
#: gamut's edge: a correct render's cyan), which is no finding.
MIN_EXPLAINED_DELTA_E = 0.05


@record
class Family:
    """A family of SAFE-COLOR transforms: its ``transforms`` (sweep names), the one-parameter
    ``fits`` that stand for it and the ``direction`` it charges (None: a mixed family, used
    only when a fit explains the chart)."""

    name: str
    transforms: tuple[str, ...]
    fits: tuple[str, ...]
    direction: str | None
    description: str


#: The transform families (module docstring), by name.
FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("tone", ("brightness-dec", "brightness-inc", "gamma-dec", "gamma-inc"),
           ("brightness", "gamma"), "lightness",
           "tone changes that keep the contrast: brightness shifts and gamma"),
    Family("chroma", ("saturation-dec", "saturation-inc"), ("saturation",), "chroma",
           "HSV saturation down or up"),
    Family("hue", ("hue",), ("hue",), "hue", "HSV hue rotation"),
    Family("contrast", ("contrast-dec", "contrast-inc"), ("contrast",), None,
           "contrast about mid-grey: lightness and chroma together"),
    Family("pull_mean", ("pull_mean",), ("pull_mean",), None,
           "every colour pulled towards the mean Lab colour"),
)}
#: The family that charges each direction of an unexplained error.
DIRECTION_FAMILY: dict[str, str] = {"lightness": "tone", "chroma": "chroma", "hue": "hue"}


@record
class FitSpec:
    """A one-parameter transform fitted to charts: the function (encoded sRGB in [0, 1]),
    its parameter range (both directions), the identity and the scan scale."""

    name: str
    family: str
    function: Callable[[ArrayLike, ArrayLike], NDArray[np.floating[Any]]]
    lo: float
    hi: float
    identity: float
    scale: str = "linear"


def _fit_specs() -> dict[str, FitSpec]:
    return {s.name: s for s in (
        FitSpec("brightness", "tone", tr.brightness, -1.0, 1.0, 0.0),
        FitSpec("gamma", "tone", tr.gamma, 0.01, 10.0, 1.0, "log"),
        FitSpec("contrast", "contrast", tr.contrast, 0.001, 50.0, 1.0, "log"),
        FitSpec("saturation", "chroma", tr.saturation, 0.001, 50.0, 1.0, "log"),
        FitSpec("hue", "hue", tr.hue, -180.0, 180.0, 0.0),
        FitSpec("pull_mean", "pull_mean", tr.pull_mean, 0.0, 1.0, 1.0),
    )}


# --------------------------------------------------------------------------------------------
# The parts of a chart error
# --------------------------------------------------------------------------------------------


def delta_e_2000_terms(lab1: ArrayLike, lab2: ArrayLike) -> tuple[F64, F64, F64, F64]:
    """The weighted CIEDE2000 terms of ``lab2`` relative to ``lab1``: ``(ΔL'/S_L, ΔC'/S_C,
    ΔH'/S_H, R_T)`` (..., each), kL = kC = kH = 1, so that ``ΔE00² = l² + c² + h² + R_T c h``.

    Sharma, Wu & Dalal, Color Res. Appl. 30(1), 2005, eq. 1-22, written out in degrees
    (independent of :func:`fidelity.colour.colorimetry.delta_e_2000`, which the tests compare
    it with).
    """
    p, q = np.broadcast_arrays(np.asarray(lab1, np.float64), np.asarray(lab2, np.float64))
    L1, a1, b1 = p[..., 0], p[..., 1], p[..., 2]
    L2, a2, b2 = q[..., 0], q[..., 1], q[..., 2]
    cbar = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2.0
    g = 0.5 * (1.0 - np.sqrt(cbar ** 7 / (cbar ** 7 + 25.0 ** 7)))
    a1p, a2p = (1.0 + g) * a1, (1.0 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.where(c1p == 0, 0.0, np.degrees(np.arctan2(b1, a1p)) % 360.0)
    h2p = np.where(c2p == 0, 0.0, np.degrees(np.arctan2(b2, a2p)) % 360.0)
    dh = h2p - h1p
    dh = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    dh = np.where(c1p * c2p == 0, 0.0, dh)
    dL, dC = L2 - L1, c2p - c1p
    dH = 2.0 * np.sqrt(c1p * c2p) * np.sin(np.radians(dh) / 2.0)
    lbar, cbarp = (L1 + L2) / 2.0, (c1p + c2p) / 2.0
    hsum = h1p + h2p
    hbar = np.where(np.abs(h1p - h2p) <= 180.0, hsum / 2.0,
                    np.where(hsum < 360.0, (hsum + 360.0) / 2.0, (hsum - 360.0) / 2.0))
    hbar = np.where(c1p * c2p == 0, hsum, hbar)
    t = (1.0 - 0.17 * np.cos(np.radians(hbar - 30.0)) + 0.24 * np.cos(np.radians(2 * hbar))
         + 0.32 * np.cos(np.radians(3 * hbar + 6.0)) - 0.20 * np.cos(np.radians(4 * hbar - 63.0)))
    sl = 1.0 + 0.015 * (lbar - 50.0) ** 2 / np.sqrt(20.0 + (lbar - 50.0) ** 2)
    sc = 1.0 + 0.045 * cbarp
    sh = 1.0 + 0.015 * cbarp * t
    dtheta = 30.0 * np.exp(-(((hbar - 275.0) / 25.0) ** 2))
    rc = 2.0 * np.sqrt(cbarp ** 7 / (cbarp ** 7 + 25.0 ** 7))
    rt = -np.sin(np.radians(2.0 * dtheta)) * rc
    return dL / sl, dC / sc, dH / sh, rt


@record
class ErrorParts:
    """A chart error split by direction (module docstring): ``lightness + chroma + hue`` =
    ``delta_e``, the mean ΔE00 over the patches; all >= 0, in ΔE00 units."""

    lightness: float
    chroma: float
    hue: float

    @property
    def delta_e(self) -> float:
        """The chart ΔE (mean ΔE00): the sum of the parts."""
        return self.lightness + self.chroma + self.hue

    def shares(self) -> dict[str, float]:
        """Each direction's share of the chart ΔE (equal thirds for a zero error)."""
        total = self.delta_e
        if total <= 0:
            return dict.fromkeys(DIRECTIONS, 1.0 / 3.0)
        return {"lightness": self.lightness / total, "chroma": self.chroma / total,
                "hue": self.hue / total}

    @property
    def dominant(self) -> str:
        """The direction with the largest part."""
        s = self.shares()
        return max(DIRECTIONS, key=lambda d: s[d])

    def to_json(self) -> dict[str, Any]:
        """``{"lightness", "chroma", "hue", "delta_e"}``."""
        return {"lightness": self.lightness, "chroma": self.chroma, "hue": self.hue,
                "delta_e": self.delta_e}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ErrorParts:
        """Inverse of :meth:`to_json`."""
        return cls(float(d["lightness"]), float(d["chroma"]), float(d["hue"]))


def error_parts(reference_lab: ArrayLike, lab: ArrayLike) -> ErrorParts:
    """Split the chart error of ``lab`` (n, 3) against ``reference_lab`` (n, 3) into its
    lightness, chroma and hue parts (module docstring; their sum is the mean ΔE00).

    Parameters
    ----------
    reference_lab
        The chart's reference CIELAB (D65), shape (n, 3): L* in [0, 100], a*, b* real.
    lab
        The measured CIELAB (D65) of the same patches, shape (n, 3).

    Returns
    -------
    ErrorParts
        The lightness, chroma and hue parts, each >= 0 in ΔE00 units; they add up to the mean
        ΔE00 of ``lab`` against ``reference_lab``.

    References
    ----------
    G. Sharma, W. Wu, E. N. Dalal, Color Res. Appl. 30(1), 21-30, 2005 (the CIEDE2000
    terms, eq. 1-22).
    """
    ref, meas = np.asarray(reference_lab, np.float64), np.asarray(lab, np.float64)
    lt, c, h, _ = delta_e_2000_terms(ref, meas)
    de = np.asarray(delta_e_2000(meas, ref), np.float64)
    sq = np.stack([lt * lt, c * c, h * h], axis=-1)
    tot = sq.sum(axis=-1, keepdims=True)
    w = np.divide(sq, tot, out=np.zeros_like(sq), where=tot > 0)
    parts = (de[..., None] * w).reshape(-1, 3).mean(axis=0)
    return ErrorParts(float(parts[0]), float(parts[1]), float(parts[2]))


# --------------------------------------------------------------------------------------------
# Fitting the transform families to a chart
# --------------------------------------------------------------------------------------------


@record
class FamilyFit:
    """The best parameter of one fitted transform (:func:`fit_families`): ``param``, the mean
    ΔE00 left between the transformed reference and the chart (``residual``), the chart's
    error before the fit (``error``: the untransformed reference against the chart) and the
    share ``explained`` = max(0, 1 - residual / error)."""

    fit: str
    family: str
    param: float
    residual: float
    error: float

    @property
    def explained(self) -> float:
        """Share of the chart error the fit removes, in [0, 1]."""
        if self.error <= 0:
            return 0.0
        return float(min(1.0, max(0.0, 1.0 - self.residual / self.error)))

    @property
    def explains(self) -> bool:
        """Whether the fit counts as an explanation: it removes at least
        :data:`MIN_EXPLAINED` of the error and :data:`MIN_EXPLAINED_DELTA_E` of mean ΔE00."""
        return (self.explained >= MIN_EXPLAINED
                and self.error - self.residual >= MIN_EXPLAINED_DELTA_E)

    def describe(self) -> str:
        """The transform and its parameter with its unit: ``brightness +0.346 (added to the
        encoded sRGB values, 0..1)``, ``gamma 0.628 (a power on linear light)``, ``contrast
        ×0.829 about mid grey``, ``saturation ×0.90 (HSV)``, ``hue +3.2° (HSV rotation)``,
        ``pull to the mean colour 0.80 (1: none)``."""
        p = self.param
        return {
            "brightness": f"brightness {p:+z.3f} (added to the encoded sRGB values, 0..1)",
            "gamma": f"gamma {p:.3f} (a power on linear light)",
            "contrast": f"contrast ×{p:.3f} about mid grey (encoded sRGB)",
            "saturation": f"saturation ×{p:.3f} (HSV)",
            "hue": f"hue {p:+z.1f}° (HSV rotation)",
            "pull_mean": f"pull to the mean colour {p:.3f} (1: none)",
        }.get(self.fit, f"{self.fit} {p:.4g}")

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, and ``explained``."""
        return {"fit": self.fit, "family": self.family, "param": self.param,
                "residual": self.residual, "error": self.error, "explained": self.explained}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FamilyFit:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["fit"]), str(d["family"]), float(d["param"]), float(d["residual"]),
                   float(d["error"]))


def _reference_srgb(reference_lab: F64) -> F64:
    return np.clip(np.asarray(lab_to_srgb(reference_lab), np.float64), 0.0, 1.0)


def fit_family(reference_lab: ArrayLike, lab: ArrayLike, fit: str,
               scan: int = 161) -> FamilyFit:
    """Fit transform ``fit`` (``brightness``, ``gamma``, ``contrast``, ``saturation``,
    ``hue``, ``pull_mean``) to a chart: the parameter minimising the mean ΔE00 between the
    transformed reference chart (reference Lab -> sRGB clipped to [0, 1], as the calibration
    chart) and ``lab``; a scan of ``scan`` points over the range, then
    a bounded Brent minimisation around the best one
    (:func:`fidelity.prediction.scalar.bounded_minimum`, the algorithm of SciPy's
    ``minimize_scalar(method="bounded")``)."""
    if fit not in _fit_specs():
        raise unknown_name("fitted transform", fit, _fit_specs())
    return _fit_all(reference_lab, lab, [fit], scan)[0]


def fit_families(reference_lab: ArrayLike, lab: ArrayLike) -> list[FamilyFit]:
    """Every fitted transform of :func:`fit_family`, best explanation first (their Brent
    searches in lockstep, :func:`fidelity.prediction.scalar.bounded_minima`: one ΔE00
    evaluation of every transform still searching per step; the same fits)."""
    fits = _fit_all(reference_lab, lab, list(_fit_specs()), 161)
    return sorted(fits, key=lambda f: -f.explained)


def _fit_all(reference_lab: ArrayLike, lab: ArrayLike, names: list[str],
             scan: int) -> list[FamilyFit]:
    specs = [_fit_specs()[n] for n in names]
    target = np.asarray(lab, np.float64)
    src = _reference_srgb(np.asarray(reference_lab, np.float64))

    def param(k: int, u: float) -> float:
        return float(np.exp(u)) if specs[k].scale == "log" else float(u)

    def costs(ks: list[int], us: list[float]) -> list[float]:
        out = np.stack([specs[k].function(src, param(k, u)) for k, u in
                        zip(ks, us, strict=True)])
        return [float(v) for v in np.mean(delta_e_2000(srgb_to_lab(out), target), axis=-1)]

    idents: list[float] = []
    best: list[tuple[float, float]] = []
    brackets: dict[int, tuple[float, float]] = {}
    for k, spec in enumerate(specs):
        log = spec.scale == "log"
        lo, hi = (math.log(spec.lo), math.log(spec.hi)) if log else (spec.lo, spec.hi)
        idents.append(math.log(spec.identity) if log else spec.identity)
        grid = np.sort(np.append(np.linspace(lo, hi, scan), idents[-1]))
        # the whole scan in one call: the chart repeated once per parameter (a transform's
        # parameter broadcasts over the leading axes; pull_mean's mean is the chart's own)
        params = np.exp(grid) if log else grid
        stack = np.broadcast_to(src, (len(grid), *src.shape))
        out = spec.function(stack, params[:, None])
        values = np.mean(delta_e_2000(srgb_to_lab(out), target), axis=-1)
        j = int(np.argmin(values))
        best.append((float(grid[j]), float(values[j])))
        a, b = float(grid[max(j - 1, 0)]), float(grid[min(j + 1, len(grid) - 1)])
        if b > a:
            brackets[k] = (a, b)
    errors = costs(list(range(len(specs))), idents)
    searching = list(brackets)
    minima = bounded_minima(
        lambda ks, us: costs([searching[k] for k in ks], us),
        [brackets[k] for k in searching],
        xatol=[1e-10 * max(1.0, abs(b - a)) for a, b in (brackets[k] for k in searching)])
    for k, (x, fx) in zip(searching, minima, strict=True):
        if fx < best[k][1]:
            best[k] = (x, fx)
    return [FamilyFit(n, spec.family, param(k, best[k][0]), best[k][1], errors[k])
            for k, (n, spec) in enumerate(zip(names, specs, strict=True))]


def fitted_lab(reference_lab: ArrayLike, fit: FamilyFit) -> F64:
    """The reference chart through a fitted transform, as Lab (n, 3)."""
    spec = _fit_specs()[fit.fit]
    src = _reference_srgb(np.asarray(reference_lab, np.float64))
    return np.asarray(srgb_to_lab(spec.function(src, fit.param)), np.float64)


def family_shares(calibration: Any = None, chart: str | None = None
                  ) -> dict[str, dict[str, float]]:
    """What each SAFE-COLOR transform moves on the calibration chart: the mean lightness,
    chroma and hue shares of its chart error over its calibrated targets (by transform)."""
    cal = calibration if calibration is not None else load_calibration_table()
    ch = load_chart(chart or DEFAULT_CHART)
    acc: dict[str, list[dict[str, float]]] = {}
    for e in cal.entries:
        if not e.reachable or e.param is None:
            continue
        out = srgb_to_lab(TRANSFORMS[e.transform](ch.srgb, e.param))
        acc.setdefault(e.transform, []).append(error_parts(ch.lab, out).shares())
    return {t: {d: float(np.mean([s[d] for s in v])) for d in DIRECTIONS}
            for t, v in acc.items()}


# --------------------------------------------------------------------------------------------
# The direction-aware table
# --------------------------------------------------------------------------------------------


@record
class DirectionalTable:
    """A direction-aware prediction table: the ``classic`` table it extends (the same file's
    curves: the worst case over every transform) and one table of worst-case curves per
    family (``families``, each a :class:`~fidelity.prediction.tablefile.PredictionTable` of kind
    ``measured``)."""

    name: str
    classic: PredictionTable
    families: dict[str, PredictionTable]
    family_transforms: dict[str, tuple[str, ...]]
    provenance: Mapping[str, Any] = field(default_factory=dict)

    @property
    def path(self) -> Any:
        """The table file."""
        return self.classic.path

    def summary(self) -> dict[str, Any]:
        """Name, kind, path and the families with their transforms."""
        return {"name": self.name, "kind": "directional",
                "path": str(self.classic.path) if self.classic.path else None,
                "families": {f: list(t) for f, t in self.family_transforms.items()}}


def load_directional_table(name_or_path: str | None = None) -> DirectionalTable:
    """Load a direction-aware table (registry name or JSON path; None:
    :data:`DEFAULT_DIRECTIONAL_TABLE`). A prediction table without ``families`` is an error
    naming it."""
    classic = load_prediction_table(name_or_path or DEFAULT_DIRECTIONAL_TABLE)
    if classic.path is None:
        return _directional_of(classic)
    return _directional_file(classic.path)


@cached_while_unchanged(maxsize=8)
def _directional_file(path: Path) -> DirectionalTable:
    """The direction-aware table in ``path``, built once a process while the file is
    unchanged."""
    return _directional_of(load_prediction_table(path))


def _directional_of(classic: PredictionTable) -> DirectionalTable:
    """:func:`load_directional_table` of a loaded table."""
    fams = classic.raw.get("families")
    if classic.kind is not TableKind.DIRECTIONAL or not isinstance(fams, dict):
        raise InputFileError(f"{classic.path or classic.name}: not a direction-aware table "
                             f"(kind {classic.kind.value!r}, no 'families'); e.g. "
                             f"{DEFAULT_DIRECTIONAL_TABLE}")
    tables: dict[str, PredictionTable] = {}
    members: dict[str, tuple[str, ...]] = {}
    for fam, body in fams.items():
        if fam not in FAMILIES:
            raise InputFileError(f"{classic.path}: unknown family {fam!r}")
        tables[fam] = parse_prediction_table(
            {"name": f"{classic.name}:{fam}", "kind": "measured",
             "interpolation": classic.interpolation, "curves": body["curves"],
             "units": classic.units}, f"{classic.path}: families.{fam}")
        members[fam] = tuple(body.get("transforms") or FAMILIES[fam].transforms)
    return DirectionalTable(classic.name, classic, tables, members,
                            dict(classic.raw.get("provenance") or {}))


# --------------------------------------------------------------------------------------------
# The prediction
# --------------------------------------------------------------------------------------------


@record
class FamilyTerm:
    """One term of a direction-aware prediction: the ``family``, its ``weight`` (in [0, 1];
    the weights add up to 1), why it is there (``reason``), and per column its curve value at
    the chart ΔE (``values``) and where it came from (``sources``: ``family`` or ``classic``,
    when the family was not measured that far)."""

    family: str
    weight: float
    reason: str
    values: Mapping[str, float | None]
    sources: Mapping[str, str]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"family": self.family, "weight": self.weight, "reason": self.reason,
                "values": dict(self.values), "sources": dict(self.sources)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FamilyTerm:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["family"]), float(d["weight"]), str(d["reason"]),
                   dict(d["values"]), dict(d["sources"]))


@record
class DirectionalPrediction:
    """The direction-aware prediction of one chart (:func:`predict_directional`): the chart
    ΔE, its :class:`ErrorParts`, the best :class:`FamilyFit` (None when none explains the
    error: :attr:`FamilyFit.explains`), the parts the fit leaves (``residual_parts``), the
    :class:`FamilyTerm` terms and the resulting loss per column (``columns``), the detector
    size asked and answered, and the table (its summary).

    Attributes
    ----------
    delta_e
        The chart ΔE (mean ΔE00) the curves were read at, >= 0.
    parts
        The chart error split into lightness, chroma and hue parts (ΔE00 units).
    fit
        The transform fit that explains most of the error; None when none removes
        :data:`MIN_EXPLAINED` of it and :data:`MIN_EXPLAINED_DELTA_E` of mean ΔE00
        (:attr:`FamilyFit.explains`).
    residual_parts
        The parts the fit leaves (the parts of the whole error without a fit).
    terms
        The family terms, largest weight first; the weights are in [0, 1] and add up to 1.
    columns
        The predicted loss per column: ``dmap_points``, ``dap_person_points``,
        ``dap_bicycle_points`` in percentage points, ``dmap_relative`` in percent of the
        baseline mAP; None where a curve has no data.
    size
        The detector size class asked (``n``, ``s``, ``m``, ``l``, ``x`` or ``any``).
    size_used
        The size class whose curves answered.
    table
        The direction-aware table's summary (name, path, sha256, ...).
    notes
        Notes on the answer, in words (what it is; where a part was charged the classic
        curve).
    standard_errors
        The sampling error of each column (:func:`combined_standard_error` of the terms'
        curve SEs); None where a curve point has none (a table without ``<column>_se``).
    """

    delta_e: float
    parts: ErrorParts
    fit: FamilyFit | None
    residual_parts: ErrorParts
    terms: tuple[FamilyTerm, ...]
    columns: Mapping[str, float | None]
    size: str
    size_used: str
    table: Mapping[str, Any]
    notes: tuple[str, ...] = ()
    standard_errors: Mapping[str, float | None] = field(default_factory=dict)

    def uncertainty(self, column: str, propagated: float = 0.0) -> float | None:
        """The standard uncertainty (k = 1) of ``column``: its sampling error and
        ``propagated`` (the chart ΔE's uncertainty through the table's slope) combined as
        uncorrelated, ``sqrt(se^2 + propagated^2)``; None where the column has no SE."""
        se = self.standard_errors.get(column)
        return None if se is None else math.hypot(se, propagated)

    @property
    def dmap_points(self) -> float | None:
        """Predicted ΔmAP, percentage points."""
        return self.columns.get("dmap_points")

    @property
    def dmap_relative(self) -> float | None:
        """Predicted ΔmAP, % of the baseline mAP."""
        return self.columns.get("dmap_relative")

    @property
    def dap_person_points(self) -> float | None:
        """Predicted person ΔAP, points."""
        return self.columns.get("dap_person_points")

    @property
    def dap_bicycle_points(self) -> float | None:
        """Predicted bicycle ΔAP, points."""
        return self.columns.get("dap_bicycle_points")

    def value(self, cls: str = "all", unit: str = "points") -> float | None:
        """The loss of ``cls`` (``all``, ``person``, ``bicycle``) in ``unit``."""
        if unit == "relative":
            if cls != "all":
                raise InvalidValueError(f"--class {cls}: only 'all' has a relative ΔmAP")
            return self.dmap_relative
        if cls not in CLASS_COLUMNS:
            raise unknown_name("class", cls, CLASS_COLUMNS)
        return self.columns.get(CLASS_COLUMNS[cls])

    def explanation(self) -> str:
        """One line: which families charge the error, with their weights (a zero error has
        none to split: its equal thirds are a convention, not a finding)."""
        if self.parts.delta_e <= 0:
            return "no colour error to split by direction"
        parts = ", ".join(f"{t.family} {100 * t.weight:.0f} %" for t in self.terms
                          if t.weight >= 0.005)
        if self.fit is not None:
            return (f"{parts}; as the SAFE-COLOR transform {self.fit.describe()}: "
                    f"{100 * self.fit.explained:.0f} % of the error")
        return f"{parts}; by direction, no transform explains the error"

    def to_json(self) -> dict[str, Any]:
        """Columns first, then the parts, fit, terms, size and table."""
        return {"delta_e": self.delta_e, **{c: self.columns.get(c) for c in COLUMNS},
                "parts": self.parts.to_json(),
                "fit": self.fit.to_json() if self.fit else None,
                "residual_parts": self.residual_parts.to_json(),
                "terms": [t.to_json() for t in self.terms], "size": self.size,
                "size_used": self.size_used, "table": dict(self.table),
                "notes": list(self.notes), "standard_errors": dict(self.standard_errors)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> DirectionalPrediction:
        """Inverse of :meth:`to_json`."""
        return cls(float(d["delta_e"]), ErrorParts.from_json(d["parts"]),
                   FamilyFit.from_json(d["fit"]) if d.get("fit") else None,
                   ErrorParts.from_json(d["residual_parts"]),
                   tuple(FamilyTerm.from_json(t) for t in d["terms"]),
                   {c: d.get(c) for c in COLUMNS}, str(d["size"]), str(d["size_used"]),
                   dict(d["table"]), tuple(str(n) for n in d.get("notes") or ()),
                   dict(d.get("standard_errors") or {}))


def _family_value(table: DirectionalTable, family: str, column: str, delta_e: float,
                  size: str) -> tuple[float | None, str]:
    """A family curve's loss at ``delta_e``; beyond the family's measured range the classic
    curve's (the classic table's rules, e.g. its total-loss ceiling)."""
    ftab = table.families[family]
    curves, _ = ftab.select(size)
    ends = [float(c.delta_e[~np.isnan(c.values[column])][-1]) for c in curves
            if np.any(~np.isnan(c.values[column]))]
    if ends and delta_e <= min(ends):
        v = float(predict_curve([delta_e], column, size=size, table=ftab)[0])
        return (None if math.isnan(v) else v), "family"
    classic = predict(delta_e, size=size, table=table.classic, transforms=False)
    return classic.columns[column].value, "classic"


def _family_se(table: DirectionalTable, family: str, column: str, delta_e: float,
               size: str, source: str) -> float | None:
    """The sampling error of a family curve's loss at ``delta_e`` (the larger SE of the
    curve points around it, as the classic table's,
    :class:`~fidelity.prediction.interpolate.SamplingError`); the classic curve's where
    ``source`` is ``classic``; None where the points state none."""
    tab = table.families[family] if source == "family" else table.classic
    got = predict(delta_e, size=size, table=tab, transforms=False).se(column)
    return None if got is None else got.high


def combined_standard_error(weights: Sequence[float], ses: Sequence[float | None]
                            ) -> float | None:
    """The sampling error of ``sum_f w_f L_f``, a weighted sum of family curve values whose
    SEs are ``ses``: ``sum_f w_f se_f``. The family cells are scored on the same images, so
    they are taken as fully correlated (correlation 1, the largest the sum can have; the
    uncorrelated ``sqrt(sum w_f^2 se_f^2)`` is never larger). None when a term of positive
    weight has no SE."""
    total = 0.0
    for w, se in zip(weights, ses, strict=True):
        if w <= 0:
            continue
        if se is None:
            return None
        total += w * se
    return total


def predict_directional(reference_lab: ArrayLike, lab: ArrayLike, *,
                        delta_e: float | None = None, size: str = "any",
                        table: DirectionalTable | str | None = None) -> DirectionalPrediction:
    """The direction-aware prediction of a chart (module docstring).

    Parameters
    ----------
    reference_lab, lab
        The chart's reference and measured CIELAB D65 (n, 3).
    delta_e
        The chart ΔE to read the curves at (default: the mean ΔE00 of ``lab`` against
        ``reference_lab``).
    size
        Detector size class (``n`` ... ``x``, ``any``).
    table
        A :class:`DirectionalTable`, its name or path (None:
        :data:`DEFAULT_DIRECTIONAL_TABLE`).

    Returns
    -------
    DirectionalPrediction
        The weighted sum of family curves at the chart ΔE, per loss column (percentage
        points; ``dmap_relative`` in percent of baseline), with the error's parts, the best
        fit and the terms; never above the classic prediction.

    Raises
    ------
    InvalidValueError
        ``delta_e`` not a finite number >= 0. Exit code 2.
    InputFileError
        A table that is missing, unreadable, or not a direction-aware table (no
        ``families``). Exit code 2.
    UnknownNameError
        An unknown table name or size class. Exit code 2.
    """
    tab = table if isinstance(table, DirectionalTable) else load_directional_table(table)
    ref = np.asarray(reference_lab, np.float64)
    meas = np.asarray(lab, np.float64)
    parts = error_parts(ref, meas)
    de = parts.delta_e if delta_e is None else float(delta_e)
    if not math.isfinite(de) or de < 0:
        raise InvalidValueError(f"ΔE {delta_e!r} must be a finite number >= 0")
    fits = fit_families(ref, meas)
    best = fits[0] if fits and fits[0].explains else None
    weights: dict[str, float] = {}
    reasons: dict[str, str] = {}
    residual = parts
    rest = 1.0
    if best is not None:
        x = best.explained
        weights[best.family] = x
        reasons[best.family] = (f"the SAFE-COLOR transform {best.describe()} explains "
                                f"{100 * x:.1f} % of the chart error")
        residual = error_parts(fitted_lab(ref, best), meas)
        rest = 1.0 - x
    shares = residual.shares()
    for d in DIRECTIONS:
        fam = DIRECTION_FAMILY[d]
        w = rest * shares[d]
        if w <= 0:
            continue
        weights[fam] = weights.get(fam, 0.0) + w
        why = f"{100 * shares[d]:.1f} % of the {'remaining ' if best else ''}error is {d}"
        reasons[fam] = f"{reasons[fam]}; {why}" if fam in reasons else why
    terms = []
    columns: dict[str, float | None] = dict.fromkeys(COLUMNS, 0.0)
    term_ses: dict[str, list[float | None]] = {c: [] for c in COLUMNS}
    classic_used = set()
    for fam, w in weights.items():
        values: dict[str, float | None] = {}
        sources: dict[str, str] = {}
        for col in COLUMNS:
            v, src = _family_value(tab, fam, col, de, size)
            values[col], sources[col] = v, src
            term_ses[col].append(_family_se(tab, fam, col, de, size, src))
            if src == "classic" and w > 0:
                classic_used.add(fam)
            cur = columns[col]
            columns[col] = None if v is None or cur is None else cur + w * v
        terms.append(FamilyTerm(fam, w, reasons[fam], values, sources))
    terms.sort(key=lambda t: -t.weight)
    _, size_used = tab.families[terms[0].family if terms else "tone"].select(size)
    notes = ["direction-aware: each part of the chart error is charged the worst loss of the "
             "transforms that move the chart that way (an empirical worst case, validated on "
             "30 camera models; not a guarantee)"]
    if classic_used:
        notes.append(f"ΔE {de:.2f} is beyond the range measured for "
                     f"{', '.join(sorted(classic_used))}: that part is charged the classic "
                     "curve")
    ws = list(weights.values())
    ses = {c: combined_standard_error(ws, term_ses[c]) for c in COLUMNS}
    return DirectionalPrediction(de, parts, best, residual, tuple(terms), columns, size,
                                 size_used, tab.summary(), tuple(notes), ses)


def predict_chart(measurement: ChartMeasurement, *, size: str = "any",
                  table: DirectionalTable | str | None = None) -> DirectionalPrediction:
    """:func:`predict_directional` of a measured chart (its reference and measured Lab of the
    patches it uses: not those left out as covered, at its mean ΔE00)."""
    used = measurement.used
    return predict_directional(measurement.reference_lab[used], measurement.lab[used],
                               delta_e=measurement.mean_delta_e, size=size, table=table)


def family_losses(delta_e: float, *, size: str = "any",
                  table: DirectionalTable | str | None = None,
                  column: str = "dmap_points") -> dict[str, tuple[float | None, str]]:
    """Each family's worst-case loss at chart ΔE ``delta_e`` (what a chart error entirely of
    that family is predicted to cost), with its source (``family`` or ``classic``)."""
    tab = table if isinstance(table, DirectionalTable) else load_directional_table(table)
    if column not in COLUMNS:
        raise unknown_name("prediction column", column, COLUMNS)
    return {f: _family_value(tab, f, column, float(delta_e), size) for f in tab.families}


def evaluate_directional(mean_delta_e: float, prediction: DirectionalPrediction,
                         criterion: Criterion, *, decision: DecisionRule | None = None,
                         delta_e_uncertainty: float | None = None,
                         loss_uncertainty: float | None = None) -> Verdict:
    """Apply a ``max-dmap`` ``criterion`` to the direction-aware prediction (a ``max-delta-e``
    criterion does not depend on the bound: :func:`fidelity.prediction.verdict.evaluate`) by
    the ``decision`` rule (default simple). ``loss_uncertainty``: the standard uncertainty a
    guarded rule takes for the direction-aware loss (:func:`fidelity.prediction.judge.
    judge_chart` gives :meth:`DirectionalPrediction.uncertainty`: its own SE with the chart
    ΔE's uncertainty through the classic slope; a table without SEs: the classic column's);
    None: U = 0."""
    rule = decision or SIMPLE
    if criterion.kind != "max-dmap":
        return evaluate(mean_delta_e, None, criterion, decision=rule,
                        delta_e_uncertainty=delta_e_uncertainty)
    return judge_value(criterion, prediction.value(criterion.cls, criterion.unit),
                       prediction.delta_e, bound="directional", decision=rule,
                       uncertainty=loss_uncertainty)


__all__ = [
    "BOUNDS",
    "COLUMNS",
    "DEFAULT_DIRECTIONAL_TABLE",
    "DIRECTIONS",
    "DIRECTION_FAMILY",
    "FAMILIES",
    "MIN_EXPLAINED",
    "MIN_EXPLAINED_DELTA_E",
    "DirectionalPrediction",
    "DirectionalTable",
    "ErrorParts",
    "Family",
    "FamilyFit",
    "FamilyTerm",
    "FitSpec",
    "combined_standard_error",
    "delta_e_2000_terms",
    "error_parts",
    "evaluate_directional",
    "family_losses",
    "family_shares",
    "fit_families",
    "fit_family",
    "fitted_lab",
    "load_directional_table",
    "predict_chart",
    "predict_directional",
]
