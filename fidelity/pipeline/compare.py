"""Sim against real: the same chart photographed by the real camera and rendered by its model.

A simulator camera is credible when it behaves like the real camera it stands for.
:func:`compare_charts` audits both images (:func:`fidelity.pipeline.check.audit_image`: any format,
the chart found or given by its corners), then compares the two charts patch by patch:

1. **Normalisation** (:data:`fidelity.correction.normalise.NORMALISATIONS`, stated in the report), applied to the simulated
   chart's linear patch colours so that it matches the real one on the neutral patches:
   ``exposure`` (default) scales it by the geometric-mean luminance ratio of the neutral
   patches (the exposure difference, in EV); ``exposure+wb`` also applies per-channel gains
   that make its neutral patches' summed R, G, B equal the real ones (a white-balance
   difference; these gains include the exposure); ``none`` compares the charts as audited.
2. **Sim-to-real ΔE**: CIEDE2000 per patch between the normalised simulated chart and the real
   chart (the real chart is the reference), its mean (the sim-to-real chart ΔE), maximum and
   the direction of each patch's difference (ΔL', ΔC', ΔH' of sim relative to real).
3. **What the difference costs a detector**: the sim-to-real chart ΔE through the prediction
   tables, classic and direction-aware (:mod:`fidelity.prediction.directional`), as if the real
   camera were the reference; with ``measure``, a colour mapping from the real chart's colours
   to the simulated chart's, fitted on the 24 patches
   (:class:`fidelity.coco.emulation.PatchEmulation`), applied to COCO photographs (as the real
   camera's images) and measured with a detector (:mod:`fidelity.coco.measure`).
4. **Verdict** of a criterion: ``max-delta-e`` on the sim-to-real chart ΔE, or ``max-dmap``
   on its predicted loss; exit codes and JUnit as ``fidelity gate``.

Each chart's own ΔE against the reference (its audit) is reported too, and the two charts'
sharpness and noise side by side (:func:`fidelity.pipeline.simreal.texture_comparison`: each
one's luminance MTF curve and neutral-patch noise, the MTF50 ratio and the SNR difference).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.chart.read import DEFAULT_READ, ReadOptions, reads_with_own_ocio
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.correction.normalise import NORMALISATIONS, normalise
from fidelity.measure.colour import measure_chart, neutral_patches
from fidelity.measure.uncertainty import UncertaintyBudget, UncertaintyComponent
from fidelity.pipeline.check import audit_image, column_intervals, evidence_of
from fidelity.pipeline.records import (
    ComparisonReport,
    Provenance,
    utc_now,
)
from fidelity.pipeline.simreal import texture_comparison
from fidelity.prediction.judge import DEFAULT_JUDGE, JudgeOptions, judge_chart

if TYPE_CHECKING:
    from fidelity.coco.measure import MeasuredLoss, MeasureRequest
    from fidelity.prediction.verdict import Criterion

def compare_charts(
    sim: str | os.PathLike[str],
    real: str | os.PathLike[str],
    *,
    sim_corners: str | Sequence[float] | None = None,
    real_corners: str | Sequence[float] | None = None,
    normalise_mode: str = "exposure",
    reference: str = "scene",
    illuminant: str = "D65",
    criterion: Criterion | None = None,
    judge: JudgeOptions = DEFAULT_JUDGE,
    read: ReadOptions = DEFAULT_READ,
    measure: MeasureRequest | None = None,
    sim_ocio_colourspace: str | None = None,
    real_ocio_colourspace: str | None = None,
) -> ComparisonReport:
    """Compare the chart in the simulated image ``sim`` with the chart in the real camera's
    image ``real`` (module docstring).

    Parameters
    ----------
    sim, real
        Images (EXR, HDR, TIFF, PNG, JPEG) of the same chart, rendered by the simulator and
        photographed by the real camera; either may be a robot recording (ROS 1 bag, ROS 2
        bag, MCAP file) of which ``read`` names the message.
    sim_corners, real_corners
        Each image's corner patch centres (see :func:`fidelity.pipeline.check.audit_image`); None: found.
    normalise_mode
        ``exposure`` (default), ``exposure+wb`` or ``none`` (:data:`fidelity.correction.normalise.NORMALISATIONS`).
    reference, illuminant
        The reference each chart's own ΔE is measured against.
    criterion
        ``max-delta-e`` on the sim-to-real chart ΔE, or ``max-dmap`` on its predicted loss
        (decided by ``judge.bound``: ``classic`` or ``directional``); None: no verdict.
    judge
        How to judge (:class:`~fidelity.prediction.judge.JudgeOptions`): the detector size
        class and prediction table of the predicted loss (each chart's own audit uses them
        too), the bound that decides a ``max-dmap`` verdict and the verdict's decision rule;
        the sim-to-real ΔE's uncertainty is :func:`sim_to_real_uncertainty`.
    read
        How both images are read (:class:`~fidelity.chart.read.ReadOptions`, as
        ``audit``); its ``topic``, ``frame`` and ``time`` apply to the input that is a robot
        recording (:mod:`fidelity.chart.recording`).
    measure
        Also measure the difference's cost on COCO (:class:`fidelity.coco.measure.MeasureRequest`).
    sim_ocio_colourspace, real_ocio_colourspace
        One image's own OpenColorIO colourspace (a render in ACEScct against a photo in
        sRGB): it replaces ``read``'s for that image, whose shared ``encoding`` and
        ``colourspace`` then describe the other
        (:func:`fidelity.chart.read.reads_with_own_ocio`).

    Returns
    -------
    ComparisonReport
        Both charts' audits, the normalisation, the sim-to-real measurement (ΔE00 per patch
        with the real chart as reference; ``mean_delta_e`` the sim-to-real chart ΔE), its
        classic and direction-aware predicted loss (percentage points, % of baseline), the
        verdict and the ΔE's uncertainty.

    Raises
    ------
    InputFileError
        A missing, unreadable or corrupt image or recording. Exit code 2.
    InvalidValueError
        No chart found in an image, corners outside it, charts with different patches, a
        ``max-dmap`` criterion without a prediction, an OpenColorIO colourspace or config
        that is not one; the message names the file. Exit code 2.
    UnknownNameError
        An unknown normalisation, reference, illuminant, table or size class. Exit code 2.
    """
    if normalise_mode not in NORMALISATIONS:
        raise unknown_name("normalisation", normalise_mode, NORMALISATIONS)
    kw: dict[str, Any] = {"reference": reference, "illuminant": illuminant,
                          "judge": JudgeOptions(judge.size, judge.table)}
    sim_read, real_read = reads_with_own_ocio((sim, real), read,
                                              (sim_ocio_colourspace, real_ocio_colourspace))
    sim_report = audit_image(sim, sim_corners, command="compare", read=sim_read, **kw)
    real_report = audit_image(real, real_corners, command="compare", read=real_read, **kw)
    sm, rm = sim_report.measurement, real_report.measurement
    if sm.patch_names != rm.patch_names:
        raise InvalidValueError(f"{sim} and {real}: the charts have different patches")
    srgb, norm = normalise(sm.srgb, rm.srgb, neutral_patches(rm), normalise_mode)
    if sim_report.neutral_ev is not None and real_report.neutral_ev is not None:
        norm = replace(norm, neutral_ev=(sim_report.neutral_ev, real_report.neutral_ev))
    norm = replace(norm, audit_auto=(sim_report.exposure_auto, real_report.exposure_auto))
    m = measure_chart(srgb, rm.lab, rm.patch_names, reference_srgb=np.clip(rm.srgb, 0, 1))
    budget = sim_to_real_uncertainty(m.mean_delta_e, sim_report.uncertainty,
                                     real_report.uncertainty)
    prediction, verdict, directional, _ = judge_chart(
        m.mean_delta_e, judge, criterion, m,
        delta_e_uncertainty=budget.combined if budget else None)
    measured: tuple[MeasuredLoss, ...] = ()
    emulation = None
    if measure is not None:
        from fidelity.coco.emulation import PatchEmulation  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        emu = PatchEmulation.fit(np.clip(rm.srgb, 0, 1), srgb, neutral_patches(rm))
        emulation = emu.describe()
        measured = tuple(measure.run(emu.apply_uint8, emu.key(), {
            "sim": str(sim), "real": str(real), "normalisation": norm.to_json(),
            "emulation": emulation}))
    conventions = {"compare": "both images audited as fidelity audit does; simulated patch "
                              "colours normalised to the real ones on the neutral patches ("
                              + norm.describe() + "); sim-to-real ΔE00 with the real chart as "
                              "the reference; the loss predicted from the sim-to-real chart "
                              "ΔE with the same tables as a chart's own ΔE"}
    prov = Provenance.collect(sim_report.provenance.input_sha256, prediction,
                              {**dict(sim_report.provenance.conventions), **conventions})

    interval, validity = evidence_of(prediction, budget, reference, judge.decision.k)
    return ComparisonReport(utc_now(), sim_report, real_report, norm, m, prediction,
                            directional, verdict, prov, judge.bound, measured, emulation,
                            uncertainty=budget, interval=interval, validity=validity,
                            intervals=column_intervals(prediction, budget, judge.decision.k),
                            texture=texture_comparison(sim_report, real_report))


def sim_to_real_uncertainty(value: float, sim: UncertaintyBudget | None,
                            real: UncertaintyBudget | None) -> UncertaintyBudget | None:
    """The standard uncertainty of a sim-to-real chart ΔE: each image's audited uncertainty
    (its chart ΔE's combined standard uncertainty) as a component, combined by root sum of
    squares. An approximation: the sim-to-real ΔE compares the two charts' colours, each known
    to the uncertainty its audit found, with a sensitivity taken as that of a chart's ΔE to its
    own colours (1). None when either audit has no budget."""
    if sim is None or real is None:
        return None
    how = ("the combined standard uncertainty of the {} image's audited chart ΔE (its own "
           "budget), sensitivity taken as 1")
    return UncertaintyBudget(
        float(value),
        (UncertaintyComponent("simulated image", sim.combined, "B", how.format("simulated")),
         UncertaintyComponent("real image", real.combined, "B", how.format("real"))),
        quantity="sim-to-real mean ΔE00")


__all__ = ["compare_charts", "sim_to_real_uncertainty"]
