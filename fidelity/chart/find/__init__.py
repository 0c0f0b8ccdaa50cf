"""Find a 24-patch colour chart in an image, so that an audit needs no hand-given corners.

The result is the same four numbers a user would give with ``--corners``: the image centres of
the dark skin, bluish green, black and white patches (:mod:`fidelity.chart.locate` conventions:
``x`` along a row, ``y`` down, pixel ``(i, j)`` at ``x = j, y = i``), with a detection
confidence. Everything after that, sampling windows, bad pixels, exposure and ΔE00, is the
audit's own and does not depend on how the corners were found.

The finder is a cascade (:func:`~fidelity.chart.find.cascade.find_chart`, method
``cascade``):

1. **Search at a reduced size.** The image is shrunk (area average) to at most
   :data:`~fidelity.chart.find.cascade.SEARCH_SIDE` pixels on its long side, its 99th
   percentile of the brightest channel scaled to 1, and sRGB-encoded to 8 bits (the
   detectors' domain: :mod:`~fidelity.chart.find.view`).
2. **Candidates** from two detectors (:mod:`~fidelity.chart.find.candidates`):

   ``mcc``
       OpenCV's Macbeth chart detector (``cv2.mcc``, opencv-contrib; Ch. Pardo et al.'s MCC
       method): each chart it finds gives its 24 patch centres, to which a grid -> image
       homography is fitted.
   ``segmentation``
       our own patch segmentation: adaptive thresholds of the grey image at
       :data:`~fidelity.chart.find.outlines.BLOCK_FRACTIONS` of the image size, contours
       simplified to convex quadrilaterals (:func:`~fidelity.chart.find.outlines.patch_quads`),
       and quadrilaterals of similar size that sit one patch pitch apart along each other's
       edges chained into a lattice (:func:`~fidelity.chart.find.lattice.patch_lattices`); a
       homography lattice -> image is fitted to their centres. Any 4 x 6 window of the
       lattice, in any of the 8 orientations of a grid (turns, mirror images), is a candidate
       placement.

   Segmentation runs first; OpenCV's detector runs only when no candidate was accepted with a
   confidence of at least :data:`~fidelity.chart.find.cascade.SURE_CONFIDENCE`.

3. **Verification** (:func:`~fidelity.chart.find.placement.placement_scores`): each placement
   of the 4 x 6 chart, including the detector's own answer moved one row or column either way
   and every orientation, samples its 24 patches (central 0.35 x 0.35 pitch) and is scored
   against the reference layout: the rank correlation (Spearman) between the measured and the
   reference patches of R, G, B, log(R/G) and log(B/G), averaged
   (:func:`~fidelity.chart.find.reference.colour_order`). Ranks do not change under a
   per-channel gain (coloured light, white balance, exposure) or a monotone tone curve, and a
   chart placed a row off, turned or mirrored mixes dark with light and grey with colour.
   The best placement is kept when its **confidence** (that mean rank correlation) is at
   least :data:`~fidelity.chart.find.cascade.MIN_CONFIDENCE`, its neutral row is in order of
   lightness (at least :data:`~fidelity.chart.find.cascade.MIN_NEUTRAL_ORDER` of the 15
   pairs), the next-best placement of the same candidate scores at least
   :data:`~fidelity.chart.find.cascade.MIN_MARGIN` lower and its patches are flat (median
   relative spread beyond white noise at most :data:`~fidelity.chart.find.cascade.MAX_UNIFORMITY`); so a chart
   found one row or column off is corrected, never measured. The thresholds were chosen on a
   tuning set of the benchmark (``python -m benchmarks.speed find_chart -p seed=7``) and
   checked on another (seed 19).
4. **Refinement at full size**: the chart's surroundings (corners plus 2 pitches) are cut from
   the full-size image (shrunk only if still larger than
   :data:`~fidelity.chart.find.cascade.REFINE_SIDE`), segmented again, each patch outline
   assigned to its grid cell, and the homography fitted to all assigned centres by the
   normalised DLT (:func:`fidelity.chart.locate.homography_from_points`), leaving out centres
   more than three times the median distance off the fit. The placement is verified again
   there and kept only if it passes the same checks.
5. **Small charts in large images**: when the whole image shows no chart and it is larger than
   1.5 x :data:`~fidelity.chart.find.cascade.SEARCH_SIDE`, four overlapping quarters are
   searched, each at up to :data:`~fidelity.chart.find.cascade.SEARCH_SIDE` pixels.

Chart types: the 24-patch ColorChecker layout (Classic, Mini, the 24-patch page of a Passport:
one layout, whose physical sizes one photo cannot tell apart). Other patch grids found beside
the chart (a Passport's other page) are counted in ``other_charts`` and not measured
(:mod:`~fidelity.chart.find.surroundings`). A chart whose 24 patches continue into a larger
grid of patches (a ColorChecker SG or a digital target), or a large patch grid with no
24-patch chart, is refused with :class:`~fidelity.core.errors.InvalidValueError` rather than
measured wrongly.

Input: ``(H, W, 3)`` linear or sRGB-encoded RGB of any scale (HDR welcome). NaN, Inf and
negative values count as black for finding the chart only.

Modules, lowest first: :mod:`~fidelity.chart.find.view` (the image as the detectors see it),
:mod:`~fidelity.chart.find.outlines` (patch outlines), :mod:`~fidelity.chart.find.lattice`
(outlines chained into lattices, homographies), :mod:`~fidelity.chart.find.reference` (the
24-patch layout and the rank scores against it), :mod:`~fidelity.chart.find.result`
(:class:`~fidelity.chart.find.result.FoundChart`,
:class:`~fidelity.chart.find.result.ChartChecks`), :mod:`~fidelity.chart.find.placement`
(placements on a lattice, verified), :mod:`~fidelity.chart.find.candidates` (the detectors),
:mod:`~fidelity.chart.find.surroundings` (what lies around the chart) and
:mod:`~fidelity.chart.find.cascade` (:func:`~fidelity.chart.find.cascade.find_chart`,
:func:`~fidelity.chart.find.cascade.check_corners`). The CFA pattern of a raw mosaic, read
from the chart in it, is :mod:`fidelity.chart.bayer`'s.

This package re-exports the names used outside it, each imported from its submodule on first use;
each is defined, and looked up at run time, in its submodule: a test or benchmark that replaces one (``monkeypatch.setattr``) replaces it
in the submodule that uses it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fidelity.core.lazy import lazy_attributes

#: Public name -> the submodule that defines it (imported on first use, PEP 562: importing
#: one submodule, such as the records' :mod:`~fidelity.chart.find.result`, loads no other).
_NAMES: dict[str, str] = {
    "DETECTORS": "fidelity.chart.find.candidates",
    "mcc_charts": "fidelity.chart.find.candidates",
    "CHART_FINDERS": "fidelity.chart.find.cascade",
    "MAX_UNIFORMITY": "fidelity.chart.find.cascade",
    "MIN_CONFIDENCE": "fidelity.chart.find.cascade",
    "MIN_IMAGE_SIDE": "fidelity.chart.find.cascade",
    "MIN_MARGIN": "fidelity.chart.find.cascade",
    "MIN_NEUTRAL_ORDER": "fidelity.chart.find.cascade",
    "REFINE_SIDE": "fidelity.chart.find.cascade",
    "SEARCH_SIDE": "fidelity.chart.find.cascade",
    "SURE_CONFIDENCE": "fidelity.chart.find.cascade",
    "check_corners": "fidelity.chart.find.cascade",
    "find_chart": "fidelity.chart.find.cascade",
    "ASSIGN_TOLERANCE": "fidelity.chart.find.lattice",
    "Lattice": "fidelity.chart.find.lattice",
    "patch_lattices": "fidelity.chart.find.lattice",
    "patch_side": "fidelity.chart.find.lattice",
    "perspective_bias": "fidelity.chart.find.lattice",
    "robust_homography": "fidelity.chart.find.lattice",
    "Quads": "fidelity.chart.find.outlines",
    "patch_quads": "fidelity.chart.find.outlines",
    "MAX_OCCLUDED": "fidelity.chart.find.placement",
    "ORIENTATIONS": "fidelity.chart.find.placement",
    "Placement": "fidelity.chart.find.placement",
    "placement_scores": "fidelity.chart.find.placement",
    "sample_cells": "fidelity.chart.find.placement",
    "colour_order": "fidelity.chart.find.reference",
    "neutral_order": "fidelity.chart.find.reference",
    "occluded_patches": "fidelity.chart.find.reference",
    "ChartChecks": "fidelity.chart.find.result",
    "FoundChart": "fidelity.chart.find.result",
    "chart_pitch": "fidelity.chart.find.surroundings",
    "other_charts": "fidelity.chart.find.surroundings",
    "Pyramid": "fidelity.chart.find.view",
    "View": "fidelity.chart.find.view",
    "detection_image": "fidelity.chart.find.view",
    "make_view": "fidelity.chart.find.view",
}

if TYPE_CHECKING:
    from fidelity.chart.find.candidates import DETECTORS, mcc_charts
    from fidelity.chart.find.cascade import (
        CHART_FINDERS,
        MAX_UNIFORMITY,
        MIN_CONFIDENCE,
        MIN_IMAGE_SIDE,
        MIN_MARGIN,
        MIN_NEUTRAL_ORDER,
        REFINE_SIDE,
        SEARCH_SIDE,
        SURE_CONFIDENCE,
        check_corners,
        find_chart,
    )
    from fidelity.chart.find.lattice import (
        ASSIGN_TOLERANCE,
        Lattice,
        patch_lattices,
        patch_side,
        perspective_bias,
        robust_homography,
    )
    from fidelity.chart.find.outlines import Quads, patch_quads
    from fidelity.chart.find.placement import (
        MAX_OCCLUDED,
        ORIENTATIONS,
        Placement,
        placement_scores,
        sample_cells,
    )
    from fidelity.chart.find.reference import colour_order, neutral_order, occluded_patches
    from fidelity.chart.find.result import ChartChecks, FoundChart
    from fidelity.chart.find.surroundings import chart_pitch, other_charts
    from fidelity.chart.find.view import Pyramid, View, detection_image, make_view


#: Import a public name's submodule on first use (PEP 562).
__getattr__ = lazy_attributes("fidelity.chart.find", _NAMES, globals())

__all__ = [
    "ASSIGN_TOLERANCE",
    "CHART_FINDERS",
    "DETECTORS",
    "MAX_OCCLUDED",
    "MAX_UNIFORMITY",
    "MIN_CONFIDENCE",
    "MIN_IMAGE_SIDE",
    "MIN_MARGIN",
    "MIN_NEUTRAL_ORDER",
    "ORIENTATIONS",
    "REFINE_SIDE",
    "SEARCH_SIDE",
    "SURE_CONFIDENCE",
    "ChartChecks",
    "FoundChart",
    "Lattice",
    "Placement",
    "Pyramid",
    "Quads",
    "View",
    "chart_pitch",
    "check_corners",
    "colour_order",
    "detection_image",
    "find_chart",
    "make_view",
    "mcc_charts",
    "neutral_order",
    "occluded_patches",
    "other_charts",
    "patch_lattices",
    "patch_quads",
    "patch_side",
    "perspective_bias",
    "placement_scores",
    "robust_homography",
    "sample_cells",
]
