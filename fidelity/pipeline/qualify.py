"""Qualification of the installed tool: its computations against independent references, run on
the user's own installation.

An assessor who signs a credibility assessment made with a tool needs confidence that the tool
computes correctly *where it ran*: ISO 26262-8 clause 11.4.9 ("validation of the software
tool") and the code verification of a simulation credibility assessment (NATM). The test suite
does this on the developers' machines; this module runs a fixed set of its reference checks on
any installation, in seconds, without test data or shared data:

========================  ==================================================================
``ciede2000``             CIEDE2000 against Sharma, Wu & Dalal (2005)'s 34 published pairs,
                          both argument orders
``srgb-matrix``           the linear-sRGB-to-XYZ matrix derived from the sRGB primaries
                          against the one IEC 61966-2-1 publishes (4 decimals)
``illuminant-white``      the white of the shipped D65 and A spectra, integrated with the CIE
                          1931 observer, against CIE 15:2018 table 2
``calibration``           the SAFE-COLOR calibration solved by this installation against the
                          paper's four published parameters (4 decimals)
``chart-baseline``        the gamut-clipped reference chart's mean ΔE00 against the paper's
                          "about 0.29"
``ideal-camera``          the closed-form render of an ideal camera (CIE 1931 sensitivities,
                          no noise) against the scene reference it must reproduce
``renderer``              the closed-form render against Mitsuba 3, a third-party spectral
                          renderer (not run where Mitsuba is not installed)
``chart-finder``          a chart put into a synthetic photo under known homographies: the
                          found corner patches against the known ones
``measurement``           the same photos audited from PNG files (find, sample, decode, Lab,
                          ΔE) against the painted colours' ΔE computed without any image
``coco-scoring``          COCO box AP (pycocotools, faster-coco-eval) against hand-computed
                          values of five cases (not run without the ``coco`` extra)
``ocio-input``            ``--ocio-colourspace ACEScct`` (this installation's OpenColorIO and
                          its built-in config) against the ACEScct curve of ACES S-2016-001
                          and the AP1-to-BT.709 matrix derived from the published
                          chromaticities with Bradford adaptation (not run without the
                          ``ocio`` extra)
``installation``          every installed file against the SHA-256 its wheel's ``RECORD``
                          lists (not run for an editable install: its source is a checkout)
========================  ==================================================================

Each check states its reference, the quantity compared, the tolerance and what it measured.
Science only: the command line (``fidelity qualify``) and the record's JSON are
:mod:`fidelity.cli.qualify` and :mod:`fidelity.report.qualify`.
"""

from __future__ import annotations

import base64
import json
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.camera import render
from fidelity.camera.mitsuba import MitsubaUnavailableError
from fidelity.camera.render import ChartLayout
from fidelity.chart import ocio
from fidelity.chart.image import write_png
from fidelity.chart.ocio import DEFAULT_CONFIG

# the implementations under qualification are looked up in their modules at each check, so
# that a check tests what the module holds when it runs
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_chart
from fidelity.colour.colorimetry import matrix_chromatic_adaptation, normalised_primary_matrix
from fidelity.colour.spectral import WAVELENGTHS_NM, load_illuminant, tristimulus
from fidelity.core.errors import FidelityError, UnknownNameError
from fidelity.core.fileio import file_sha256
from fidelity.core.record import record
from fidelity.core.resources import resource_dir
from fidelity.measure.colour import chart_delta_e
from fidelity.pipeline.check import audit_image
from fidelity.pipeline.records import ImageSource
from fidelity.prediction.calibration import calibrate_transform, transform_delta_e

if TYPE_CHECKING:
    from importlib.metadata import Distribution

#: Status of a check that ran and met its tolerance / did not / could not run here.
PASS, FAIL, NOT_RUN = "pass", "fail", "not run"

#: IEC 61966-2-1:1999, clause 5.2: linear sRGB (D65) to CIE XYZ, as published (4 decimals).
IEC_61966_2_1_MATRIX: tuple[tuple[float, float, float], ...] = (
    (0.4124, 0.3576, 0.1805), (0.2126, 0.7152, 0.0722), (0.0193, 0.1192, 0.9505))
#: CIE 15:2018 table 2: tristimulus values of the white (Y = 100) under D65 and A, 2° observer.
CIE_15_WHITES: Mapping[str, tuple[float, float, float]] = {
    "D65": (95.047, 100.0, 108.883), "A": (109.850, 100.0, 35.585)}
#: SAFE-COLOR's published calibration parameters (4 decimals): (transform, target ΔE, value).
PAPER_PARAMETERS: tuple[tuple[str, float, float], ...] = (
    ("contrast-dec", 1.0, 0.9535), ("gamma-inc", 12.0, 1.5509), ("hue", 3.0, 5.3371),
    ("pull_mean", 6.0, 0.7263))
#: SAFE-COLOR: the gamut-clipped chart "sits at a mean ΔE00 of about 0.29 from the reference".
PAPER_BASELINE_DELTA_E: float = 0.29
#: The top-level folders of the installed distribution whose files the installation check
#: compares with the wheel's RECORD.
PACKAGES: tuple[str, ...] = ("fidelity",)
#: Synthetic photos of the chart-finder check: the chart's corners in a 1280 x 960 frame
#: (clockwise from the dark-skin corner): nearly frontal, oblique, turned by 180°.
FINDER_SCENES: tuple[tuple[tuple[float, float], ...], ...] = (
    ((330.0, 250.0), (900.0, 300.0), (880.0, 700.0), (300.0, 640.0)),
    ((200.0, 180.0), (1050.0, 330.0), (1000.0, 760.0), (260.0, 860.0)),
    ((980.0, 720.0), (360.0, 700.0), (380.0, 300.0), (960.0, 280.0)),
)


@record
class QualificationCheck:
    """One check of the installed tool against an independent reference.

    ``deviation`` is the measured ``quantity`` (in ``unit``), compared with ``tolerance``:
    the check passes when ``deviation <= tolerance``; None when it did not run or its
    computation raised an error (a failed check; ``detail`` says why). ``cases``: how many
    comparisons the deviation is the largest of."""

    name: str
    subject: str
    reference: str
    quantity: str
    unit: str
    tolerance: float
    deviation: float | None
    cases: int
    status: str
    detail: str = ""
    seconds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """JSON form: every field."""
        return {"name": self.name, "status": self.status, "subject": self.subject,
                "reference": self.reference, "quantity": self.quantity, "unit": self.unit,
                "deviation": self.deviation, "tolerance": self.tolerance,
                "cases": self.cases, "detail": self.detail, "seconds": self.seconds}


@record
class Qualification:
    """The checks run on this installation (:func:`qualify`)."""

    checks: tuple[QualificationCheck, ...]
    seconds: float = 0.0

    @property
    def failed(self) -> tuple[QualificationCheck, ...]:
        """The checks that ran and missed their tolerance."""
        return tuple(c for c in self.checks if c.status == FAIL)

    @property
    def not_run(self) -> tuple[QualificationCheck, ...]:
        """The checks that could not run here."""
        return tuple(c for c in self.checks if c.status == NOT_RUN)

    @property
    def qualified(self) -> bool:
        """Every check that ran passed, and at least one ran."""
        return not self.failed and len(self.not_run) < len(self.checks)


@record
class _Spec:
    subject: str
    reference: str
    quantity: str
    unit: str
    tolerance: float
    measure: Callable[[], tuple[float, int, str]]


class CheckNotRunError(FidelityError):
    """A check that cannot run on this installation (the reason is the message)."""


def sharma_pairs() -> np.ndarray:
    """Sharma, Wu & Dalal (2005), table 1: 34 rows of L1, a1, b1, L2, a2, b2, ΔE00."""
    return np.loadtxt(resource_dir("data") / "references" / "ciede2000_sharma2005.txt")


def _ciede2000() -> tuple[float, int, str]:
    pairs = sharma_pairs()
    lab1, lab2, published = pairs[:, :3], pairs[:, 3:6], pairs[:, 6]
    dev = np.maximum(np.abs(cm.delta_e_2000(lab1, lab2) - published),
                     np.abs(cm.delta_e_2000(lab2, lab1) - published))
    worst = int(np.argmax(dev))
    return float(dev[worst]), 2 * len(pairs), f"largest at pair {worst + 1}"


def _srgb_matrix() -> tuple[float, int, str]:
    dev = np.abs(np.asarray(cm.MATRIX_LINEAR_SRGB_TO_XYZ) - np.asarray(IEC_61966_2_1_MATRIX))
    return float(dev.max()), dev.size, "derived from the sRGB primaries and D65's chromaticity"


def _illuminant_white() -> tuple[float, int, str]:
    worst, where = 0.0, ""
    for name, published in CIE_15_WHITES.items():
        _, white = tristimulus(np.ones(WAVELENGTHS_NM.size), load_illuminant(name).on_grid())
        rel = np.abs(np.asarray(white, np.float64) * 100 / np.asarray(published) - 1)
        if float(rel.max()) >= worst:
            worst, where = float(rel.max()), f"largest for {name} {'XYZ'[int(np.argmax(rel))]}"
    return worst, 3 * len(CIE_15_WHITES), where


def _calibration() -> tuple[float, int, str]:
    worst, where, reached = 0.0, "", 0.0
    for transform, target, paper in PAPER_PARAMETERS:
        ours = calibrate_transform(transform, target).param
        if ours is None:
            return float("inf"), len(PAPER_PARAMETERS), f"{transform} at ΔE {target:g}: unreachable"
        if abs(ours - paper) >= worst:
            worst, where = abs(ours - paper), f"largest for {transform} at ΔE {target:g}"
        reached = max(reached, abs(float(transform_delta_e(transform, paper)) - target) / target)
    return worst, len(PAPER_PARAMETERS), (f"{where}; the paper's parameters reach their targets "
                                          f"within {reached * 100:.2f} % here (the paper: 0.3 %)")


def _chart_baseline() -> tuple[float, int, str]:
    chart = load_chart("safecolor")
    value = chart_delta_e(chart.srgb, chart.lab)
    return abs(value - PAPER_BASELINE_DELTA_E), 1, f"measured {value:.4f}"


def _ideal_camera() -> tuple[float, int, str]:
    r = render.render_chart("ideal", "D65")
    return r.measurement.mean_delta_e, 24, f"largest patch {r.measurement.max_delta_e:.4f}"


def _renderer() -> tuple[float, int, str]:
    closed = render.render_chart("ideal", "D65")
    try:
        mits = render.render_chart("ideal", "D65", renderer="mitsuba", spp=64, pixels_per_patch=16)
    except (ImportError, MitsubaUnavailableError) as exc:
        raise CheckNotRunError(f"Mitsuba 3 does not render here ({exc})") from None
    d = cm.delta_e_2000(closed.measurement.lab, mits.measurement.lab)
    return float(np.mean(d)), int(d.size), (f"Mitsuba {mits.variant}, 64 samples per pixel; "
                                            f"largest patch {float(np.max(d)):.4f}")


def synthetic_photo(corners: Sequence[Sequence[float]], patch_px: int = 64, seed: int = 7,
                    size: tuple[int, int] = (1280, 960)) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """A photo of the SAFE-COLOR chart (its gamut-clipped sRGB in 8-bit codes, black gaps) put
    by a homography onto a smooth coloured background: ``(H, W, 3)`` display sRGB in [0, 1],
    the true centres ``(4, 2)`` of the dark-skin, bluish-green, black and white patches (x, y;
    pixel centres at integer coordinates), and the painted codes ``(24, 3)`` / 255.
    ``corners``: where the chart's outer corners go (clockwise from dark skin's)."""
    import cv2

    chart = load_chart("safecolor")
    layout = ChartLayout.for_patch_size(patch_px)
    painted = np.round(np.clip(chart.srgb, 0.0, 1.0) * 255.0) / 255.0
    image = layout.paint(painted, background=0.03).astype(np.float32)
    w, h = size
    src = np.array([[-0.5, -0.5], [layout.width - 0.5, -0.5],
                    [layout.width - 0.5, layout.height - 0.5], [-0.5, layout.height - 0.5]],
                   np.float32)
    m = cv2.getPerspectiveTransform(src, np.asarray(corners, np.float32))
    rng = np.random.default_rng(seed)
    wave = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 25)
    background = np.clip(0.45 + 8.0 * wave[..., None] * np.array([1.0, 0.8, 1.2], np.float32),
                         0.0, 1.0)
    warped = cv2.warpPerspective(image, m, (w, h), flags=cv2.INTER_LINEAR)
    cover = cv2.warpPerspective(np.ones(image.shape[:2], np.float32), m, (w, h),
                                flags=cv2.INTER_LINEAR)[..., None]
    photo = warped + (1.0 - cover) * background
    centres = []
    for i in (0, layout.cols - 1, layout.rows * layout.cols - 1, (layout.rows - 1) * layout.cols):
        y0, y1, x0, x1 = layout.patch_box(i)
        centres.append([(x0 + x1 - 1) / 2, (y0 + y1 - 1) / 2])
    truth = cv2.perspectiveTransform(np.asarray(centres, np.float64)[None], m)[0]
    return np.clip(photo, 0.0, 1.0), truth, painted


_AUDITS: dict[int, tuple[float, float, float]] = {}


def _audit_scenes() -> list[tuple[float, float, float]]:
    """Each finder scene written as an 8-bit PNG and audited from the file (reference
    ``safecolor``): (corner error in % of the patch pitch, measured mean ΔE00, the painted
    colours' mean ΔE00). Run once for both checks that read them in one :func:`qualify`."""
    if not _AUDITS:
        lab = load_chart("safecolor").lab
        with tempfile.TemporaryDirectory(prefix="fidelity-qualify-") as tmp:
            for k, corners in enumerate(FINDER_SCENES):
                photo, truth, painted = synthetic_photo(corners, seed=7 + k)
                path = write_png(Path(tmp) / f"scene-{k}.png", photo, 8)
                report = audit_image(path, reference="safecolor")
                if not isinstance(report.source, ImageSource):  # pragma: no cover
                    raise TypeError("an image audit reports an image source")
                found = np.asarray(report.source.corners, np.float64)
                pitch = float(np.linalg.norm(truth[1] - truth[0])) / 5.0
                error = float(np.max(np.linalg.norm(found - truth, axis=1))) / pitch * 100.0
                _AUDITS[k] = (error, report.measurement.mean_delta_e,
                              chart_delta_e(painted, lab))
    return [_AUDITS[k] for k in sorted(_AUDITS)]


def _chart_finder() -> tuple[float, int, str]:
    errors = [a[0] for a in _audit_scenes()]
    return max(errors), 4 * len(errors), "corner errors " + ", ".join(f"{e:.2f} %" for e in errors)


def _measurement() -> tuple[float, int, str]:
    scenes = _audit_scenes()
    dev = [abs(measured - painted) for _, measured, painted in scenes]
    return max(dev), len(scenes), "measured " + ", ".join(f"{m:.4f}" for _, m, _ in scenes) + (
        f" against {scenes[0][2]:.4f}")


#: Hand-computed COCO box AP (101-point interpolation, IoU .50:.05:.95): (ground truth
#: {image: [(category id, x, y, w, h)]}, detections {image: [(x, y, w, h, score, class
#: index)]}, mAP, AP50).
COCO_CASES: tuple[tuple[str, dict[int, list[tuple[float, ...]]],
                        dict[int, list[tuple[float, ...]]], float, float], ...] = (
    ("a perfect detection", {1: [(1, 10, 10, 50, 80)]}, {1: [(10, 10, 50, 80, 0.9, 0)]},
     1.0, 1.0),
    # a false positive ranked first: precision 1/2 at recall 1
    ("a false positive ranked first", {1: [(1, 10, 10, 50, 80)]},
     {1: [(120, 120, 40, 40, 0.95, 0), (10, 10, 50, 80, 0.9, 0)]}, 0.5, 0.5),
    # shifted by 10 px on 100 x 100: IoU 90/110 = 0.818, a hit at 7 of the 10 thresholds
    ("a box at IoU 0.818", {1: [(3, 0, 0, 100, 100)]}, {1: [(10, 0, 100, 100, 0.8, 2)]},
     0.7, 1.0),
    # one of two images' objects found: AP person 1, bicycle 0, their mean
    ("an image missed", {1: [(1, 10, 10, 50, 80)], 2: [(2, 0, 0, 60, 60)]},
     {1: [(10, 10, 50, 80, 0.9, 0)]}, 0.5, 0.5),
    # half the objects found, no false positive: precision 1 up to recall 0.5, 51 of 101 points
    ("half the objects found", {1: [(1, 10, 10, 50, 80)], 2: [(1, 0, 0, 60, 60)]},
     {1: [(10, 10, 50, 80, 0.9, 0)]}, 51 / 101, 51 / 101),
)


#: ACES AP1 primaries and the ACES white (S-2014-004), Rec. ITU-R BT.709 primaries and D65
#: (IEC 61966-2-1), CIE 1931 xy.
AP1_XY = ((0.713, 0.293), (0.165, 0.830), (0.128, 0.044))
ACES_WHITE_XY = (0.32168, 0.33767)
BT709_XY = ((0.640, 0.330), (0.300, 0.600), (0.150, 0.060))
D65_XY = (0.3127, 0.3290)


def acescct_encode(linear: np.ndarray) -> np.ndarray:
    """ACEScct code values of linear AP1 values (ACES S-2016-001, section 4.4)."""
    lin = np.asarray(linear, np.float64)
    log = (np.log2(np.maximum(lin, 1e-30)) + 9.72) / 17.52
    return np.where(lin <= 0.0078125, 10.5402377416545 * lin + 0.0729055341958355, log)


def _ocio_input() -> tuple[float, int, str]:
    try:
        import PyOpenColorIO  # noqa: F401
    except ImportError:
        raise CheckNotRunError("OpenColorIO is not installed (the ocio extra)") from None

    def white(xy: tuple[float, float]) -> np.ndarray:
        return np.array([xy[0] / xy[1], 1.0, (1.0 - xy[0] - xy[1]) / xy[1]])

    matrix = (np.linalg.inv(normalised_primary_matrix(BT709_XY, D65_XY))
              @ matrix_chromatic_adaptation(white(ACES_WHITE_XY), white(D65_XY), "Bradford")
              @ normalised_primary_matrix(AP1_XY, ACES_WHITE_XY))
    greys = (0.001, 0.005, 0.0078125, 0.02, 0.18, 0.5, 1.0, 4.0)  # the toe, its end, the log
    linear = np.array([(g, g, g) for g in greys] + [(0.18, 0.05, 0.02), (0.02, 0.18, 0.05),
                                                     (0.05, 0.02, 0.18), (0.6, 0.3, 0.1)])
    got, how = ocio.convert(acescct_encode(linear)[None].astype(np.float32), "ACEScct",
                       DEFAULT_CONFIG)
    want = linear @ matrix.T
    rel = np.abs(got[0] - want) / np.maximum(np.abs(want).max(axis=-1, keepdims=True), 1e-3)
    return (float(rel.max()), rel.size,
            f"OpenColorIO {how.version}, {how.config_name} -> {how.target}")


def _coco_scoring() -> tuple[float, int, str]:
    try:
        from fidelity.coco.detectors import COCO80_CATEGORY_IDS, COCO80_NAMES  # noqa: PLC0415 (the COCO benchmark, loaded at the call)
        from fidelity.coco.scoring import coco_from_dict, evaluate_detections, scorer_available  # noqa: PLC0415 (the COCO benchmark, loaded at the call)
    except ImportError as exc:
        raise CheckNotRunError(f"the coco extra is not installed ({exc})") from None
    methods = [m for m in ("pycocotools", "faster-coco-eval") if scorer_available(m)]
    if not methods:
        raise CheckNotRunError("no COCO scorer is installed (the coco extra)")
    cats = [{"id": c, "name": n} for c, n in zip(COCO80_CATEGORY_IDS, COCO80_NAMES,
                                                 strict=True)]
    worst, where = 0.0, ""
    for name, truth, found, map_, map50 in COCO_CASES:
        images = [{"id": i, "width": 200, "height": 200, "file_name": f"{i}.jpg"} for i in truth]
        anns = [{"id": k + 1, "image_id": i, "category_id": c, "bbox": [x, y, w, h],
                 "area": w * h, "iscrowd": 0}
                for k, (i, (c, x, y, w, h)) in enumerate((i, a) for i in truth for a in truth[i])]
        gt = coco_from_dict({"images": images, "annotations": anns, "categories": cats})
        dets = {i: np.array([[x, y, x + w, y + h, s, k] for x, y, w, h, s, k in rows])
                for i, rows in found.items()}
        for method in methods:
            score = evaluate_detections(gt, dets, sorted(truth), method=method)
            dev = max(abs(score.map - map_), abs(score.map50 - map50))
            if dev >= worst:
                worst, where = dev, f"largest for {name} ({method})"
    return worst, 2 * len(COCO_CASES) * len(methods), f"{', '.join(methods)}; {where}"


def _record_digest(path: Path) -> str:
    """A file's SHA-256 as a wheel's RECORD writes it (URL-safe base64, no padding)."""
    digest = bytes.fromhex(file_sha256(path))
    return base64.urlsafe_b64encode(digest).rstrip(b"=").decode()


def installed_files(dist: Distribution) -> tuple[int, list[str]]:
    """Check every file of the package (:data:`PACKAGES`) that the ``RECORD`` of ``dist``
    lists with a SHA-256 (the wheel installer's record of what it wrote; the console scripts,
    written outside the package for the interpreter at hand, are not checked): how many were
    checked, and each one changed or missing (``"path: changed"``). Raises :class:`CheckNotRunError` for an editable install
    or a distribution without a ``RECORD``."""
    direct = dist.read_text("direct_url.json")
    if direct and json.loads(direct).get("dir_info", {}).get("editable"):
        raise CheckNotRunError("an editable install: the package is its source checkout, "
                               "whose commit and changes the record's tool entry states")
    files = [(f, f.hash.value) for f in dist.files or ()
             if f.hash is not None and f.hash.mode == "sha256" and f.parts[0] in PACKAGES]
    if not files:
        raise CheckNotRunError("the installation lists no file with its SHA-256 (no RECORD)")
    bad = []
    for f, digest in files:
        path = Path(str(f.locate()))
        if not path.is_file():
            bad.append(f"{f}: missing")
        elif _record_digest(path) != digest:
            bad.append(f"{f}: changed")
    return len(files), bad


def _installation() -> tuple[float, int, str]:
    from importlib import metadata  # not at module level: a check loads this module

    try:
        dist = metadata.distribution("camera-fidelity")
    except metadata.PackageNotFoundError:
        raise CheckNotRunError("camera-fidelity is not installed (run from a source folder)") \
            from None
    n, bad = installed_files(dist)
    return float(len(bad)), n, "; ".join(bad[:5]) + (f"; {len(bad) - 5} more" if len(bad) > 5
                                                    else "")


#: The checks by name, in the order they run.
QUALIFICATION_CHECKS: Mapping[str, _Spec] = {
    "ciede2000": _Spec(
        "CIEDE2000 colour difference",
        "Sharma, Wu & Dalal (2005), Color Res. Appl. 30(1), table 1: 34 pairs, 4 decimals",
        "largest |ΔE00 - published|", "ΔE00", 1e-4, _ciede2000),
    "srgb-matrix": _Spec(
        "linear sRGB to CIE XYZ matrix", "IEC 61966-2-1:1999 clause 5.2, 4 decimals",
        "largest |element - published|", "", 5e-5, _srgb_matrix),
    "illuminant-white": _Spec(
        "spectral integration (illuminant spectra, CIE 1931 2° observer)",
        "CIE 15:2018 table 2: white tristimulus of D65 and A",
        "largest relative |XYZ - published|", "", 5e-4, _illuminant_white),
    "calibration": _Spec(
        "SAFE-COLOR transforms and their calibration on the chart",
        "SAFE-COLOR's published parameters (contrast-dec ΔE 1, gamma-inc ΔE 12, hue ΔE 3, "
        "pull_mean ΔE 6; 4 decimals)", "largest |parameter - published|", "", 1e-3,
        _calibration),
    "chart-baseline": _Spec(
        "reference chart and its gamut clipping", "SAFE-COLOR: the clipped chart's mean ΔE00 "
        "is about 0.29", "|mean ΔE00 - 0.29|", "ΔE00", 5e-3, _chart_baseline),
    "ideal-camera": _Spec(
        "closed-form spectral render", "closed form: an ideal camera (CIE 1931 "
        "sensitivities, no noise, D65) reproduces the scene reference", "mean ΔE00", "ΔE00",
        1e-2, _ideal_camera),
    "renderer": _Spec(
        "closed-form spectral render", "Mitsuba 3 rendering the same chart spectrally",
        "mean ΔE00 between the renders", "ΔE00", 5e-2, _renderer),
    "chart-finder": _Spec(
        "chart finder", "closed form: 3 synthetic photos with the chart under known "
        "homographies", "largest corner-patch centre error", "% of the patch pitch", 1.0,
        _chart_finder),
    "measurement": _Spec(
        "image audit (PNG read, chart found, windows sampled, decoded, ΔE00)",
        "the painted colours' mean ΔE00 computed without an image",
        "largest |measured - painted| mean ΔE00", "ΔE00", 5e-3, _measurement),
    "coco-scoring": _Spec(
        "COCO box AP (the scorers behind every measured ΔmAP)",
        "hand-computed AP of 5 cases (101-point interpolation, IoU .50:.95)",
        "largest |mAP or AP50 - hand-computed|", "", 1e-6, _coco_scoring),
    "ocio-input": _Spec(
        "OpenColorIO input conversion (--ocio-colourspace)",
        "ACES S-2016-001 (ACEScct) and the AP1-to-BT.709 matrix from the published "
        "chromaticities, Bradford-adapted", "largest relative |linear - reference|", "", 1e-4,
        _ocio_input),
    "installation": _Spec(
        "installed files", "the wheel's RECORD (SHA-256 of every file installed)",
        "changed or missing", "files", 0.0, _installation),
}


def run_check(name: str) -> QualificationCheck:
    """Run the check ``name`` of :data:`QUALIFICATION_CHECKS`."""
    try:
        return _run(name)
    finally:
        _AUDITS.clear()


def _run(name: str) -> QualificationCheck:
    if name not in QUALIFICATION_CHECKS:
        raise UnknownNameError(f"qualification check {name!r}: one of "
                               f"{', '.join(QUALIFICATION_CHECKS)}")
    spec = QUALIFICATION_CHECKS[name]
    start = time.perf_counter()
    try:
        deviation, cases, detail = spec.measure()
    except CheckNotRunError as exc:
        return QualificationCheck(name, spec.subject, spec.reference, spec.quantity, spec.unit,
                                  spec.tolerance, None, 0, NOT_RUN, str(exc),
                                  time.perf_counter() - start)
    except Exception as exc:  # noqa: BLE001 - a computation that breaks fails its check
        return QualificationCheck(name, spec.subject, spec.reference, spec.quantity, spec.unit,
                                  spec.tolerance, None, 0, FAIL,
                                  f"raised {type(exc).__name__}: {exc}",
                                  time.perf_counter() - start)
    ok = bool(np.isfinite(deviation)) and deviation <= spec.tolerance
    return QualificationCheck(name, spec.subject, spec.reference, spec.quantity, spec.unit,
                              spec.tolerance, float(deviation), cases, PASS if ok else FAIL,
                              detail, time.perf_counter() - start)


def qualify(names: Iterable[str] | None = None) -> Qualification:
    """Run the checks ``names`` (default: all of :data:`QUALIFICATION_CHECKS`, in order)."""
    start = time.perf_counter()
    try:
        checks = tuple(_run(n) for n in (QUALIFICATION_CHECKS if names is None else names))
    finally:
        _AUDITS.clear()
    return Qualification(checks, time.perf_counter() - start)


__all__ = ["CIE_15_WHITES", "FAIL", "IEC_61966_2_1_MATRIX", "NOT_RUN", "PAPER_BASELINE_DELTA_E",
           "PAPER_PARAMETERS", "PASS", "QUALIFICATION_CHECKS", "CheckNotRunError",
           "Qualification", "QualificationCheck", "installed_files", "qualify", "run_check",
           "sharma_pairs", "synthetic_photo"]
