"""The direction-aware bound and the blind-spot checks on the validation's 30 cameras.

:func:`compare_bounds` takes the validation's measured cells (:class:`MeasuredCell`: each
camera's measured ΔmAP ± SE per detector and the classic prediction; built from
:class:`fidelity.coco.validate.colour.ValidationResults` by
:func:`fidelity.coco.validate.colour.directional_validation`) and, for every camera
(:class:`CameraChart`), renders its chart in closed form under the test case's illuminant
(when the camera file is given; else it reads the chart stored with the results),
predicts its loss with the direction-aware table (:mod:`fidelity.prediction.directional`,
detector size ``n``) and runs the blind-spot checks (:mod:`fidelity.measure.blindspots`). Per
(camera, detector) cell and class it compares both bounds with the measured loss:

- *within*: measured <= predicted; *within 2 SE*: measured − 2 SE <= predicted;
- the *over-prediction ratio* predicted / measured, where the measured loss is positive (a
  ratio of a loss indistinguishable from 0 says little: :attr:`CellBounds.significant`
  marks the cells measured more than 2 SE above 0).

Its record (:class:`DirectionalValidation`) goes into ``validation.json`` under
``directional`` and into the validation report.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.camera.render import render_chart
from fidelity.coco.loss import LOSS_COLUMNS, Losses
from fidelity.core.record import record
from fidelity.measure.blindspots import BlindSpot, chart_blind_spots
from fidelity.measure.colour import measure_chart
from fidelity.prediction.directional import (
    DEFAULT_DIRECTIONAL_TABLE,
    DirectionalPrediction,
    load_directional_table,
    predict_directional,
)

if TYPE_CHECKING:
    from fidelity.measure.blindspots import BlindSpot
    from fidelity.prediction.directional import DirectionalPrediction


@record
class MeasuredCell:
    """One (camera, detector) cell of the validation as the bounds read it: the camera's chart
    ΔE, the ``measured`` losses and their ``se`` (points, relative in %), and the ``classic``
    prediction of the bound table (:class:`fidelity.coco.loss.Losses` each)."""

    camera: str
    model: str
    chart_delta_e: float
    measured: Losses
    se: Losses
    classic: Losses


@record
class CameraChart:
    """A camera's chart as stored with the validation: its mean ΔE00 ``chart_delta_e`` and
    ``patches`` (per patch ``name``, ``lab``, ``reference_lab``, ``srgb``); with the camera
    file (``path``) and the scene ``illuminant`` the chart is rendered again in closed form
    (and its bit depth read) instead, its reference adapted to D65 with ``cat``."""

    camera: str
    chart_delta_e: float
    patches: tuple[Mapping[str, Any], ...]
    path: Path | None = None
    illuminant: str | None = None
    cat: str = "Bradford"


@record
class BoundCell:
    """One class of one (camera, detector) cell: measured loss and SE, both predictions, and
    for each whether it holds (``*_within``, ``*_within_2se``) and its over-prediction ratio
    (None where the measured loss is not positive)."""

    measured: float | None
    se: float | None
    classic: float | None
    directional: float | None

    def _within(self, predicted: float | None, sigmas: float) -> bool | None:
        if predicted is None or self.measured is None:
            return None
        return self.measured - sigmas * (self.se or 0.0) <= predicted

    @property
    def classic_within(self) -> bool | None:
        """Measured <= classic prediction."""
        return self._within(self.classic, 0.0)

    @property
    def classic_within_2se(self) -> bool | None:
        """Measured − 2 SE <= classic prediction."""
        return self._within(self.classic, 2.0)

    @property
    def directional_within(self) -> bool | None:
        """Measured <= direction-aware prediction."""
        return self._within(self.directional, 0.0)

    @property
    def directional_within_2se(self) -> bool | None:
        """Measured − 2 SE <= direction-aware prediction."""
        return self._within(self.directional, 2.0)

    def ratio(self, predicted: float | None) -> float | None:
        """predicted / measured (None when the measured loss is not positive)."""
        if predicted is None or self.measured is None or self.measured <= 0:
            return None
        return predicted / self.measured

    @property
    def significant(self) -> bool:
        """The measured loss is more than 2 SE above 0."""
        return (self.measured is not None and self.se is not None
                and self.measured > 2.0 * self.se)

    def to_json(self) -> dict[str, Any]:
        """Values, checks and ratios."""
        return {"measured": self.measured, "se": self.se, "classic": self.classic,
                "directional": self.directional, "classic_within": self.classic_within,
                "classic_within_2se": self.classic_within_2se,
                "directional_within": self.directional_within,
                "directional_within_2se": self.directional_within_2se,
                "classic_ratio": self.ratio(self.classic),
                "directional_ratio": self.ratio(self.directional),
                "significant": self.significant}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BoundCell:
        """Inverse of :meth:`to_json` (the derived keys are computed again)."""
        return cls(d.get("measured"), d.get("se"), d.get("classic"), d.get("directional"))


@record
class CameraBounds:
    """A camera's direction-aware prediction (detector size n), its blind-spot checks and
    whether its chart was rendered now (``rendered``) or read from the results."""

    camera: str
    chart_delta_e: float
    prediction: DirectionalPrediction
    blind_spots: tuple[BlindSpot, ...]
    rendered: bool

    @property
    def warnings(self) -> list[BlindSpot]:
        """The checks that found a risk."""
        return [b for b in self.blind_spots if b.at_risk]

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return {"camera": self.camera, "chart_delta_e": self.chart_delta_e,
                "prediction": self.prediction.to_json(),
                "blind_spots": [b.to_json() for b in self.blind_spots],
                "rendered": self.rendered}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CameraBounds:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["camera"]), float(d["chart_delta_e"]),
                   DirectionalPrediction.from_json(d["prediction"]),
                   tuple(BlindSpot.from_json(b) for b in d.get("blind_spots") or ()),
                   bool(d.get("rendered", False)))


@record
class RowBounds:
    """Both bounds of one (camera, detector) cell, per class of
    :data:`fidelity.coco.loss.LOSS_COLUMNS`."""

    camera: str
    model: str
    chart_delta_e: float
    cells: Mapping[str, BoundCell]

    def to_json(self) -> dict[str, Any]:
        """``{"camera", "model", "chart_delta_e", "cells": {class: ...}}``."""
        return {"camera": self.camera, "model": self.model,
                "chart_delta_e": self.chart_delta_e,
                "cells": {k: c.to_json() for k, c in self.cells.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RowBounds:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["camera"]), str(d["model"]), float(d["chart_delta_e"]),
                   {k: BoundCell.from_json(c) for k, c in d["cells"].items()})


@record
class ClassBounds:
    """One class over every cell: how often each bound holds (plainly and within 2 SE) and
    the median over-prediction ratio (over the cells measured above 0, and over those
    measured more than 2 SE above 0)."""

    cells: int
    classic_within: int
    classic_within_2se: int
    directional_within: int
    directional_within_2se: int
    classic_median_ratio: float | None
    directional_median_ratio: float | None
    classic_median_ratio_significant: float | None
    directional_median_ratio_significant: float | None
    significant_cells: int

    def to_json(self) -> dict[str, Any]:
        """Field names as keys."""
        return dict(self.__dict__)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ClassBounds:
        """Inverse of :meth:`to_json`."""
        def ratio(key: str) -> float | None:
            v = d.get(key)
            return None if v is None else float(v)

        return cls(int(d["cells"]), int(d["classic_within"]), int(d["classic_within_2se"]),
                   int(d["directional_within"]), int(d["directional_within_2se"]),
                   ratio("classic_median_ratio"), ratio("directional_median_ratio"),
                   ratio("classic_median_ratio_significant"),
                   ratio("directional_median_ratio_significant"), int(d["significant_cells"]))


@record
class DirectionalValidation:
    """Both bounds on the validation's cells (module docstring): the direction-aware
    ``table``, per camera its :class:`CameraBounds`, per cell its :class:`RowBounds` and per
    class a :class:`ClassBounds` summary."""

    table: str
    cameras: Mapping[str, CameraBounds]
    rows: tuple[RowBounds, ...]
    summary: Mapping[str, ClassBounds]

    def to_json(self) -> dict[str, Any]:
        """``validation.json``'s ``directional`` object."""
        return {"table": self.table,
                "summary": {k: s.to_json() for k, s in self.summary.items()},
                "cameras": {k: c.to_json() for k, c in self.cameras.items()},
                "rows": [r.to_json() for r in self.rows]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> DirectionalValidation:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["table"]), {k: CameraBounds.from_json(c)
                                     for k, c in d["cameras"].items()},
                   tuple(RowBounds.from_json(r) for r in d["rows"]),
                   {k: ClassBounds.from_json(s) for k, s in d["summary"].items()})


def _median(values: Sequence[float | None]) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.median(v)) if v else None


def summarise(rows: Sequence[RowBounds], cls: str) -> ClassBounds:
    """The :class:`ClassBounds` of one class."""
    return summarise_cells([r.cells[cls] for r in rows])


def summarise_cells(measured: Sequence[BoundCell]) -> ClassBounds:
    """The :class:`ClassBounds` of ``measured`` (the cells without a measured loss left out):
    the validation's per class, the COCO-C table's (:meth:`fidelity.coco.corruptions.
    CocoCResults.bounds`)."""
    cells = [c for c in measured if c.measured is not None]
    sig = [c for c in cells if c.significant]
    return ClassBounds(
        len(cells), sum(bool(c.classic_within) for c in cells),
        sum(bool(c.classic_within_2se) for c in cells),
        sum(bool(c.directional_within) for c in cells),
        sum(bool(c.directional_within_2se) for c in cells),
        _median([c.ratio(c.classic) for c in cells]),
        _median([c.ratio(c.directional) for c in cells]),
        _median([c.ratio(c.classic) for c in sig]),
        _median([c.ratio(c.directional) for c in sig]), len(sig))


def compare_bounds(cells: Sequence[MeasuredCell], charts: Mapping[str, CameraChart],
                   table: str | None = None) -> DirectionalValidation:
    """Both bounds and the blind-spot checks on every camera and cell (module docstring).

    Parameters
    ----------
    cells
        The measured cells with the classic prediction; a cell whose camera has no chart is
        left out.
    charts
        Per camera its chart (rendered again where the camera file is given).
    table
        The direction-aware table's name or path (None:
        :data:`fidelity.prediction.directional.DEFAULT_DIRECTIONAL_TABLE`).
    """
    tab = load_directional_table(table)
    cameras: dict[str, CameraBounds] = {}
    for name, chart in sorted(charts.items()):
        if chart.path is not None and chart.illuminant is not None:
            render = render_chart(str(chart.path), chart.illuminant, cat=chart.cat)
            m = render.measurement
            ref, lab, de = m.reference_lab, m.lab, m.mean_delta_e
            spots = chart_blind_spots(m, bits=render.camera.quantisation_bits)
            rendered = True
        else:
            lab = np.array([p["lab"] for p in chart.patches], dtype=np.float64)
            ref = np.array([p["reference_lab"] for p in chart.patches], dtype=np.float64)
            srgb = np.array([p["srgb"] for p in chart.patches], dtype=np.float64)
            m = measure_chart(srgb, ref, [str(p["name"]) for p in chart.patches])
            de = chart.chart_delta_e
            spots = chart_blind_spots(m)
            rendered = False
        pred = predict_directional(ref, lab, delta_e=de, size="n", table=tab)
        cameras[name] = CameraBounds(name, float(de), pred, spots, rendered)
    rows = []
    for r in cells:
        cam = cameras.get(r.camera)
        if cam is None:
            continue
        bounds = {cls: BoundCell(r.measured.get(col), r.se.get(col), r.classic.get(col),
                                 cam.prediction.columns.get(col))
                  for cls, col in LOSS_COLUMNS.items()}
        rows.append(RowBounds(r.camera, r.model, r.chart_delta_e, bounds))
    summary = {cls: summarise(rows, cls) for cls in LOSS_COLUMNS}
    return DirectionalValidation(table or DEFAULT_DIRECTIONAL_TABLE, cameras, tuple(rows),
                                 summary)


__all__ = [
    "BoundCell",
    "CameraBounds",
    "CameraChart",
    "ClassBounds",
    "DirectionalValidation",
    "MeasuredCell",
    "RowBounds",
    "compare_bounds",
    "summarise",
]
