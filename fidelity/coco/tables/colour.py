"""Colour's tables: the SAFE-COLOR comparison, the chart ΔE limits and ``tables.json``.

What ``fidelity tables`` computes (:func:`tables_result`, :class:`TablesResult`, written as
``tables.json``): the :class:`~fidelity.coco.tables.build.Tables` of the sweep of SAFE-COLOR's
colour transforms, checked against the paper's findings (``shared/reference/safecolor.md``,
:func:`compare_with_paper`: harm ranking, worst transforms, the ΔE 3 / 6 / 12 thresholds, the
safety classes) and the chart ΔE limits the measured worst cases imply
(:func:`delta_e_limits`). The report (Markdown, HTML, plots) is :mod:`fidelity.report.coco`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.tables.build import Tables, build_tables, merge_tables
from fidelity.coco.tables.grid import SAFETY_CLASSES, CellDelta
from fidelity.coco.tables.prediction import prediction_table
from fidelity.coco.tables.worst import WorstCaseRow
from fidelity.core.fileio import json_ready
from fidelity.core.record import record
from fidelity.prediction.table import delta_e_limit
from fidelity.prediction.tablefile import parse_prediction_table

if TYPE_CHECKING:
    from fidelity.coco.sweep import SweepStore


@record
class PaperFinding:
    """One SAFE-COLOR finding checked against our measurements (:func:`compare_with_paper`):
    the ``claim``, our ``verdict`` ("agrees", "disagrees", "not enough data", qualified) and
    the ``evidence`` in words and numbers."""

    claim: str
    verdict: str
    evidence: str

    def to_json(self) -> dict[str, str]:
        """``{"claim", "verdict", "evidence"}``."""
        return {"claim": self.claim, "verdict": self.verdict, "evidence": self.evidence}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PaperFinding:
        """Inverse of :meth:`to_json`."""
        return cls(d["claim"], d["verdict"], d["evidence"])


@record
class BudgetLimit:
    """The largest chart ΔE (None: none) whose predicted loss in ``column`` stays within
    ``budget``; ``status`` as :class:`fidelity.prediction.table.DeltaELimit` says it."""

    column: str
    budget: float
    delta_e: float | None
    status: str

    def to_json(self) -> dict[str, Any]:
        """``{"column", "budget", "delta_e", "status"}``."""
        return {"column": self.column, "budget": self.budget, "delta_e": self.delta_e,
                "status": self.status}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BudgetLimit:
        """Inverse of :meth:`to_json`."""
        return cls(d["column"], float(d["budget"]), d.get("delta_e"), d["status"])


@record
class CurveLimits:
    """The ΔE limits of one curve of the measured table (:func:`delta_e_limits`): a size
    class's worst case (``model`` None) or one model's."""

    size: str
    model: str | None
    limits: tuple[BudgetLimit, ...]

    def to_json(self) -> dict[str, Any]:
        """``{"size", "model", "limits"}``."""
        return {"size": self.size, "model": self.model,
                "limits": [x.to_json() for x in self.limits]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CurveLimits:
        """Inverse of :meth:`to_json`."""
        return cls(d["size"], d.get("model"),
                   tuple(BudgetLimit.from_json(x) for x in d["limits"]))


@record
class TablesResult:
    """What ``fidelity tables`` computes: the :class:`~fidelity.coco.tables.build.Tables`, the
    paper comparison and the ΔE limits; :meth:`to_json` is ``tables.json``."""

    tables: Tables
    comparison: tuple[PaperFinding, ...]
    limits: tuple[CurveLimits, ...]

    def to_json(self) -> dict[str, Any]:
        """``{"tables", "comparison", "delta_e_limits"}`` (strict JSON values)."""
        out: dict[str, Any] = json_ready({
            "tables": self.tables.to_json(), "comparison": [c.to_json() for c in self.comparison],
            "delta_e_limits": [x.to_json() for x in self.limits]})
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TablesResult:
        """Inverse of :meth:`to_json` (reads ``tables.json``)."""
        return cls(Tables.from_json(d["tables"]),
                   tuple(PaperFinding.from_json(c) for c in d["comparison"]),
                   tuple(CurveLimits.from_json(x) for x in d.get("delta_e_limits") or ()))


def tables_result(store: SweepStore, coco: Any = None, *, progress: bool = False,
                  images: Mapping[str, int] | None = None,
                  earlier: tuple[Tables, Mapping[str, Any]] | None = None) -> TablesResult:
    """:func:`~fidelity.coco.tables.build.build_tables` with its paper comparison and ΔE limits
    (``tables.json``); ``earlier``: (tables, source) whose models the store does not hold are
    kept (:func:`~fidelity.coco.tables.build.merge_tables`)."""
    tables = build_tables(store, coco, progress=progress, images=images)
    if earlier is not None:
        tables = merge_tables(tables, *earlier)
    return TablesResult(tables, tuple(compare_with_paper(tables)),
                        tuple(delta_e_limits(tables)))


def _loss_and_se(r: WorstCaseRow, key: str) -> tuple[float | None, float | None]:
    """A worst-case row's loss ``key`` (``dmap_points`` or ``dmap_relative``) and its SE."""
    if key == "dmap_points":
        return r.dmap_points, r.dmap_points_se
    return r.dmap_relative, r.dmap_relative_se


def _beyond_noise(rows: Sequence[WorstCaseRow], key: str, bound: float) -> bool:
    """Whether some row's ``key`` exceeds ``bound`` by more than 2 of its standard errors
    (a row without an SE counts when it exceeds at all)."""
    for r in rows:
        v, se = _loss_and_se(r, key)
        if v is not None and v > bound + (2 * se if se else 0.0):
            return True
    return False


def _threshold_verdict(rows: Sequence[WorstCaseRow], bound: float) -> str:
    """The verdict on "worst-case ΔmAP stays below ``bound`` %" over worst-case ``rows``.

    The paper's "%" may be points or a share of the baseline, so both are tested: "agrees" if
    every relative loss is below the bound; "agrees if read as points" if only the points are;
    else "disagrees". Each exceedance is qualified "within 2 SE" where no row exceeds the
    bound by more than twice its standard error in that unit, else "beyond 2 SE" (the worst
    case over ten noisy transforms is biased upwards by about one SE); without standard
    errors, unqualified.
    """
    rel = max((r.dmap_relative or 0.0) for r in rows)
    pts = max((r.dmap_points or 0.0) for r in rows)
    if rel < bound:
        return "agrees"

    def by(key: str) -> str:
        if not any(_loss_and_se(r, key)[1] for r in rows):  # no standard errors: no qualifier
            return ""
        return " (beyond 2 SE)" if _beyond_noise(rows, key, bound) else " (within 2 SE)"

    if pts < bound:
        return f"agrees if read as points; exceeded as a share of baseline{by('dmap_relative')}"
    return (f"disagrees: exceeded in points{by('dmap_points')} and as a share of "
            f"baseline{by('dmap_relative')}")


#: SAFE-COLOR's thresholds: worst-case ΔmAP below ``bound`` % up to chart ΔE ``limit``.
PAPER_THRESHOLDS: tuple[tuple[int, float], ...] = ((3, 1.0), (6, 3.0), (12, 10.0))


#: Transforms SAFE-COLOR names as the worst up to ΔE 24.
PAPER_WORST: frozenset[str] = frozenset({"contrast-inc", "contrast-dec", "saturation-inc"})


def compare_with_paper(tables: Tables) -> list[PaperFinding]:
    """Check the SAFE-COLOR findings against our measurements; one :class:`PaperFinding` each.

    Verdicts are "agrees", "disagrees" or "not enough data" (qualified where the data are
    incomplete or the exceedance is within the noise).
    """
    cells = [r for rows in tables.cells.values() for r in rows if r.done]
    out = _ranking_findings(tables, cells)
    out += _worst_transform_findings(tables, cells)
    out += _threshold_findings(tables)
    out += _safety_class_findings(cells)
    return out


def _ranking_findings(tables: Tables, cells: Sequence[CellDelta]) -> list[PaperFinding]:
    """Harm ranking, per model: mean relative ΔmAP per transform over the ΔE values <= 12
    (every transform reaches them on the chart) at which that model has all transforms; the
    overall ranking averages the per-model means."""
    planned = list(tables.transforms)
    vals: dict[tuple[str, str, float], float] = {
        (r.model, r.transform, r.delta_e): r.dmap_relative for r in cells
        if r.dmap_relative is not None}
    per_model: dict[str, dict[str, float]] = {}
    used: dict[str, list[float]] = {}
    for m in sorted(tables.cells):
        common = sorted(d for d in {k[2] for k in vals if k[0] == m}
                        if d <= 12 and all((m, t, d) in vals for t in planned))
        if common and max(common) >= 6:  # at ΔE < 6 losses are within the scatter
            used[m] = common
            per_model[m] = {t: float(np.mean([vals[(m, t, d)] for d in common]))
                            for t in planned}
    most = "contrast increase and decrease hurt detection most"
    least = "hue changes hurt least"
    if not per_model:
        return [PaperFinding(claim, "not enough data",
                             "no model has all transforms at a ΔE in 6..12 yet")
                for claim in (most, least)]
    mean = {t: float(np.mean([pm[t] for pm in per_model.values()])) for t in planned}
    order = sorted(mean, key=mean.__getitem__, reverse=True)
    ranks = {m: sorted(pm, key=pm.__getitem__, reverse=True) for m, pm in per_model.items()}
    ev = ", ".join(f"{t} {mean[t]:.2f} %" for t in order)
    lists = {m: ", ".join(f"{d:g}" for d in ds) for m, ds in used.items()}
    if len(set(lists.values())) == 1:
        which = "every model" if len(used) > 1 else next(iter(used))
        where = f"mean relative ΔmAP ({which} at ΔE {next(iter(lists.values()))}): "
    else:
        where = ("mean relative ΔmAP ("
                 + "; ".join(f"{m} at ΔE {lists[m]}" for m in used) + "): ")
    top = {"contrast-inc", "contrast-dec"}
    per = "; ".join(f"{m}: top two {', '.join(r[:2])}, mildest {r[-1]}"
                    for m, r in ranks.items())
    return [
        PaperFinding(most, "agrees" if set(order[:2]) == top
                     else "partly agrees" if set(order[:2]) & top else "disagrees",
                     where + ev + ". Per model: " + per),
        PaperFinding(least, "agrees" if order[-1] == "hue" else "disagrees",
                     f"mildest: {order[-1]} ({mean[order[-1]]:.2f} %); hue "
                     f"{mean['hue']:.2f} %, rank {order.index('hue') + 1} of "
                     f"{len(order)} (1 = most harmful)") if "hue" in mean else
        PaperFinding(least, "not enough data", "the sweep has no hue cells (transforms "
                     f"swept: {', '.join(order)})"),
    ]


def noise_floor(cells: Sequence[CellDelta]) -> tuple[float | None, list[float]]:
    """The smallest ΔE measured and the relative ΔmAP of every done cell there: the scatter
    that any small perturbation of the images causes on this image set."""
    low_de = min((r.delta_e for r in cells if r.done), default=None)
    low = [r.dmap_relative for r in cells if r.done and r.delta_e == low_de
           and r.dmap_relative is not None]
    return low_de, low


def _worst_transform_findings(tables: Tables, cells: Sequence[CellDelta]
                              ) -> list[PaperFinding]:
    """The worst transform, only where the worst loss stands out of the scatter: twice the sd
    of the relative ΔmAP over all cells at the smallest ΔE (measured noise floor)."""
    low_de, low = noise_floor(cells)
    floor = 2 * float(np.std(low, ddof=1)) if len(low) >= 3 else 0.0
    worst = [(r.worst_transform, r.delta_e, r.partial)
             for rows in tables.worst_case.values() for r in rows
             if r.worst_transform and r.delta_e <= 24 and (r.dmap_relative or 0) > floor]
    if not worst:
        return []
    wset = {w for w, _, _ in worst}
    others = sorted(f"{w} at ΔE {d:g}" for w, d, _ in worst if w not in PAPER_WORST)
    verdict = "agrees" if wset <= PAPER_WORST else "disagrees"
    if any(p for _, _, p in worst):
        verdict = "so far " + verdict + " (incomplete)"
    return [PaperFinding(
        "worst case up to ΔE 24 is contrast-inc, contrast-dec or saturation-inc", verdict,
        f"rows whose worst relative ΔmAP exceeds the noise floor {floor:.2f} % (2 sd at ΔE "
        f"{low_de:g}): worst transforms " + ", ".join(sorted(wset))
        + (f"; exceptions: {', '.join(others)}" if others else ""))]


def _threshold_findings(tables: Tables) -> list[PaperFinding]:
    """"ΔE ≤ limit keeps worst-case ΔmAP below bound %", for each of :data:`PAPER_THRESHOLDS`."""
    out = []
    for limit, bound in PAPER_THRESHOLDS:
        claim = f"ΔE ≤ {limit} keeps worst-case ΔmAP below {bound:g} %"
        at_limit = [(m, r) for m, rows in tables.worst_case.items() for r in rows
                    if 0 < r.delta_e <= limit]
        if not at_limit:
            out.append(PaperFinding(claim, "not enough data", "no cells"))
            continue
        m_rel, r_rel = max(at_limit, key=lambda mr: mr[1].dmap_relative or 0)
        m_pts, r_pts = max(at_limit, key=lambda mr: mr[1].dmap_points or 0)
        rel, pts = r_rel.dmap_relative, r_pts.dmap_points
        se = r_pts.dmap_points_se
        verdict = _threshold_verdict([r for _, r in at_limit], bound)
        pts_text = f"{pts:.2f}" + (f" ± {se:.2f} SE" if se else "")
        se_rel = r_rel.dmap_relative_se
        rel_text = f"{rel:.2f} %" + (f" ± {se_rel:.2f} SE" if se_rel else "")
        if r_pts.rare is not None:
            pts_text += (f", of which {r_pts.rare.dmap_points_rare:.2f} from the "
                         f"{r_pts.rare.rare_classes} classes with at most "
                         f"{tables.rare_boxes} boxes")
        partial = any(r.partial for _, r in at_limit)
        missing_de = sorted({d for d in (1, 2, 3, 4, 5, 6, 8, 10, 12) if d <= limit}
                            - {r.delta_e for _, r in at_limit})
        if not verdict.startswith("disagrees") and (partial or missing_de):
            verdict = "so far " + verdict + " (incomplete)"
        out.append(PaperFinding(
            claim, verdict,
            f"largest relative loss {rel_text} ({m_rel}, {r_rel.worst_transform} at ΔE "
            f"{r_rel.delta_e:g}); largest loss in points {pts_text} ({m_pts}, "
            f"{r_pts.worst_transform} at ΔE {r_pts.delta_e:g}); "
            f"{sum(r.transforms_done for _, r in at_limit)} cells"
            + (f"; ΔE not yet measured: {missing_de}" if missing_de else "")))
    return out


def _safety_class_findings(cells: Sequence[CellDelta]) -> list[PaperFinding]:
    """Person and bicycle more sensitive than the mean: relative ΔAP > relative ΔmAP in most
    cells with ΔmAP > 0.5 %."""
    out = []
    for cls in SAFETY_CLASSES:
        more = total = 0
        for r in cells:
            rel_c = r.dap_relative(cls)
            if rel_c is None or r.dmap_relative is None or r.dmap_relative <= 0.5:
                continue
            total += 1
            more += rel_c > r.dmap_relative
        out.append(PaperFinding(
            f"{cls} is more sensitive than the mean (relative ΔAP > ΔmAP)",
            "not enough data" if total == 0 else ("agrees" if more > total / 2 else "disagrees"),
            f"{cls} lost more (relative) than mAP in {more} of {total} cells with ΔmAP > 0.5 %"))
    return out


#: Loss budgets of :func:`delta_e_limits`: the paper's 1 / 3 / 10, read both ways.
LIMIT_BUDGETS: tuple[tuple[str, float], ...] = (
    ("dmap_relative", 1.0), ("dmap_relative", 3.0), ("dmap_relative", 10.0),
    ("dmap_points", 1.0), ("dmap_points", 3.0), ("dmap_points", 10.0))


def delta_e_limits(tables: Tables) -> list[CurveLimits]:
    """The chart ΔE limits the measured worst cases imply, against the paper's ΔE 3 / 6 / 12.

    For every curve of the measured prediction table (each size class's worst case over its
    models, and each model's), the largest chart ΔE whose predicted loss stays within each of
    :data:`LIMIT_BUDGETS` (:func:`fidelity.prediction.table.delta_e_limit`: the curves as
    ``fidelity predict`` uses them, running maximum, linear between the measured ΔE).
    """
    table = parse_prediction_table(json_ready(prediction_table(tables)))
    out = []
    for curve in table.curves:
        if len(curve.delta_e) < 2:  # only the baseline measured: nothing to say
            continue
        one = replace(table, curves=(curve,))
        limits = []
        for column, budget in LIMIT_BUDGETS:
            lim = delta_e_limit(budget, column, size=curve.size, table=one)
            limits.append(BudgetLimit(column, budget, lim.delta_e, lim.status))
        out.append(CurveLimits(curve.size, curve.model, tuple(limits)))
    return out


__all__ = [
    "LIMIT_BUDGETS",
    "PAPER_THRESHOLDS",
    "PAPER_WORST",
    "BudgetLimit",
    "CurveLimits",
    "PaperFinding",
    "TablesResult",
    "compare_with_paper",
    "delta_e_limits",
    "noise_floor",
    "tables_result",
]
