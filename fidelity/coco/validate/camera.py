"""What the validation records of a camera: colour's chart, error profile and emulation.

A camera's record (:class:`CameraRecord`, kept in the store's ``cases`` table and in
``validation.json``) holds the closed-form render of its chart under the test case's
illuminant (mean and largest CIEDE2000 over the 24 patches, the patches, the direction of
the error: :func:`chart_error_profile`), its fitted colour emulation
(:class:`EmulationRecord`) and how far that moves real photos (:func:`image_delta_e`). All of
it is colour's; a second property's camera record (its chart value, its emulation) would sit
beside these.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.camera.model import read_camera_file
from fidelity.camera.render import render_chart
from fidelity.coco.emulation import AccuracySummary
from fidelity.coco.validate.suite import DEFAULT_CAT
from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.camera.model import CameraModel
    from fidelity.camera.render import ChartRender
    from fidelity.coco.emulation import AccuracySummary, Emulation
    from fidelity.coco.validate.suite import CameraCase
    from fidelity.measure.colour import ChartMeasurement


#: Images and pixel stride used for the image-level ΔE00 of an emulation (analysis only).
IMAGE_DE_SAMPLE: tuple[int, int] = (50, 4)


@record
class ErrorProfile:
    """The direction of a chart measurement's error (:func:`chart_error_profile`).

    Mean absolute unweighted CIEDE2000 components ΔL', ΔC', ΔH' and their shares of the sum;
    signed means of ΔL' (lighter > 0) and ΔC' (more chroma > 0); the lightness-contrast ratio
    std(L*)/std(L*_ref); the mean a*, b* cast of the neutral patches; the ``dominant``
    component; the worst patch and its ΔE00.
    """

    mean_abs_dl: float
    mean_abs_dc: float
    mean_abs_dh: float
    share_l: float
    share_c: float
    share_h: float
    mean_dl: float
    mean_dc: float
    contrast_ratio: float
    neutral_cast_ab: tuple[float, float]
    dominant: str
    worst_patch: str
    worst_patch_delta_e: float

    def to_json(self) -> dict[str, Any]:
        """The profile as the store keeps it (field names as keys, in field order)."""
        return {"mean_abs_dl": self.mean_abs_dl, "mean_abs_dc": self.mean_abs_dc,
                "mean_abs_dh": self.mean_abs_dh, "share_l": self.share_l,
                "share_c": self.share_c, "share_h": self.share_h, "mean_dl": self.mean_dl,
                "mean_dc": self.mean_dc, "contrast_ratio": self.contrast_ratio,
                "neutral_cast_ab": list(self.neutral_cast_ab), "dominant": self.dominant,
                "worst_patch": self.worst_patch,
                "worst_patch_delta_e": self.worst_patch_delta_e}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ErrorProfile:
        """Inverse of :meth:`to_json`."""
        cast = d["neutral_cast_ab"]
        return cls(d["mean_abs_dl"], d["mean_abs_dc"], d["mean_abs_dh"], d["share_l"],
                   d["share_c"], d["share_h"], d["mean_dl"], d["mean_dc"], d["contrast_ratio"],
                   (cast[0], cast[1]), d["dominant"], d["worst_patch"],
                   d["worst_patch_delta_e"])


@record
class ImageDeltaE:
    """How far an emulation moves real photos (:func:`image_delta_e`): mean and 95th
    percentile CIEDE2000 over every ``pixel_stride``-th pixel of ``images`` images."""

    mean: float
    p95: float
    images: int
    pixel_stride: int

    def to_json(self) -> dict[str, Any]:
        """``{"mean", "p95", "images", "pixel_stride"}``."""
        return {"mean": self.mean, "p95": self.p95, "images": self.images,
                "pixel_stride": self.pixel_stride}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ImageDeltaE:
        """Inverse of :meth:`to_json`."""
        return cls(d["mean"], d["p95"], int(d["images"]), int(d["pixel_stride"]))


@record
class EmulationRecord:
    """A camera's fitted emulation: its ``description`` (provenance as
    :meth:`fidelity.coco.emulation.Emulation.describe` gives it: method, training set, matrix,
    fit time), its ``accuracy``, the accuracy of the ``other_methods`` fitted the same way and,
    in results, the ``holdout`` accuracy (fitted without the chart spectra)."""

    description: dict[str, Any]
    accuracy: AccuracySummary
    other_methods: dict[str, AccuracySummary]
    holdout: AccuracySummary | None = None

    def to_json(self) -> dict[str, Any]:
        """The description's keys, then ``accuracy``, ``other_methods`` (and ``holdout``)."""
        d = self.description | {"accuracy": self.accuracy.to_json(),
                                "other_methods": {k: v.to_json()
                                                  for k, v in self.other_methods.items()}}
        if self.holdout is not None:
            d["holdout"] = self.holdout.to_json()
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EmulationRecord:
        """Inverse of :meth:`to_json`."""
        hold = d.get("holdout")
        return cls({k: v for k, v in d.items()
                    if k not in ("accuracy", "other_methods", "holdout")},
                   AccuracySummary.from_json(d["accuracy"]),
                   {k: AccuracySummary.from_json(v)
                    for k, v in (d.get("other_methods") or {}).items()},
                   AccuracySummary.from_json(hold) if hold else None)


@record
class CameraRecord:
    """A camera's chart, prediction inputs and emulation, as the store keeps it
    (:func:`~fidelity.coco.validate.colour.prepare_case`).

    ``chart_delta_e``/``chart_max_delta_e``: mean and largest CIEDE2000 over the 24 patches
    of the closed-form render under the case's illuminant, against the scene reference adapted
    to D65 with the case's transform ``cat`` (:func:`case_chart`; Bradford in stores written
    before it was recorded, as they were); ``profile``: its
    :class:`ErrorProfile`; ``render`` and ``patches``: the render's conventions and per-patch
    values (provenance, JSON); ``emulation``: :class:`EmulationRecord`; ``image_delta_e``:
    :class:`ImageDeltaE` (None in stores written before it was recorded); ``seconds``: the time
    the record took.
    """

    camera: str
    file: str
    sha256: str
    description: str
    illuminant: str
    chart_delta_e: float
    chart_max_delta_e: float
    profile: ErrorProfile
    render: dict[str, Any]
    patches: tuple[dict[str, Any], ...]
    emulation: EmulationRecord
    image_delta_e: ImageDeltaE | None
    seconds: float
    cat: str = DEFAULT_CAT

    def to_json(self) -> dict[str, Any]:
        """The record as the store and ``validation.json`` hold it (``cat`` only where it is
        not :data:`~fidelity.coco.validate.suite.DEFAULT_CAT`, so that the records of
        Bradford's cases read as they did before the transform was recorded)."""
        d: dict[str, Any] = {
            "camera": self.camera, "file": self.file, "sha256": self.sha256,
            "description": self.description, "illuminant": self.illuminant,
            "chart_delta_e": self.chart_delta_e, "chart_max_delta_e": self.chart_max_delta_e,
            "profile": self.profile.to_json(), "render": self.render,
            "patches": list(self.patches), "emulation": self.emulation.to_json()}
        if self.image_delta_e is not None:
            d["image_delta_e"] = self.image_delta_e.to_json()
        d["seconds"] = self.seconds
        if self.cat != DEFAULT_CAT:  # absent: Bradford, as every record written before it
            d["cat"] = self.cat
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CameraRecord:
        """Inverse of :meth:`to_json`."""
        ide = d.get("image_delta_e")
        return cls(d["camera"], d["file"], d["sha256"], d["description"], d["illuminant"],
                   d["chart_delta_e"], d["chart_max_delta_e"],
                   ErrorProfile.from_json(d["profile"]), dict(d.get("render") or {}),
                   tuple(d.get("patches") or ()), EmulationRecord.from_json(d["emulation"]),
                   ImageDeltaE.from_json(ide) if ide else None, d.get("seconds", 0.0),
                   str(d.get("cat", DEFAULT_CAT)))


def case_chart(case: CameraCase, camera: CameraModel | None = None, *,
               frame: bool = False) -> ChartRender:
    """The validation's chart of a test case: the closed-form render of ``camera`` (None: the
    case's camera file) under the case's illuminant, measured against the scene reference
    adapted to D65 with the case's chromatic adaptation transform (``case.cat``: the suite
    file's ``[cat]`` or ``default_cat``, or ``--cat``), as ``fidelity suite`` and ``check`` of
    the suite measure it; ``frame``: also the turned chart the properties are measured on."""
    cam = camera if camera is not None else read_camera_file(case.path)
    return render_chart(cam, case.illuminant, cat=case.cat, frame=frame)


def chart_error_profile(measurement: ChartMeasurement) -> ErrorProfile:
    """Describe a chart measurement's error direction (for the analysis of bound failures).

    Mean absolute unweighted CIEDE2000 components ΔL', ΔC', ΔH' (Sharma et al. 2005) and
    their share of the sum; signed mean ΔL' (lighter > 0) and ΔC' (more chroma > 0); the
    lightness-contrast ratio std(L*)/std(L*_ref) over the 24 patches; the mean a*, b* shift of
    the six neutral patches (white-balance cast); the worst patch.
    """
    dl, dc, dh = (np.asarray(v, float) for v in (measurement.delta_l, measurement.delta_c,
                                                 measurement.delta_h))
    lab, ref = np.asarray(measurement.lab, float), np.asarray(measurement.reference_lab, float)
    comp = np.array([np.abs(dl).mean(), np.abs(dc).mean(), np.abs(dh).mean()])
    share = comp / comp.sum() if comp.sum() > 0 else np.zeros(3)
    neutral = slice(18, 24)
    cast = (lab[neutral, 1:] - ref[neutral, 1:]).mean(axis=0)
    de = np.asarray(measurement.delta_e, float)
    return ErrorProfile(
        mean_abs_dl=float(comp[0]), mean_abs_dc=float(comp[1]), mean_abs_dh=float(comp[2]),
        share_l=float(share[0]), share_c=float(share[1]), share_h=float(share[2]),
        mean_dl=float(dl.mean()), mean_dc=float(dc.mean()),
        contrast_ratio=float(lab[:, 0].std() / ref[:, 0].std()),
        neutral_cast_ab=(float(cast[0]), float(cast[1])),
        dominant=("lightness", "chroma", "hue")[int(np.argmax(comp))],
        worst_patch=measurement.patch_names[int(np.argmax(de))],
        worst_patch_delta_e=float(de.max()),
    )


def image_delta_e(emu: Emulation, images: Sequence[np.ndarray]) -> ImageDeltaE:
    """Mean and 95th-percentile CIEDE2000 between images and their emulations (every
    ``IMAGE_DE_SAMPLE[1]``-th pixel in both directions): how far the camera moves real photos."""
    step = IMAGE_DE_SAMPLE[1]
    vals = []
    for img in images:
        a = img[::step, ::step]
        b = emu.apply_uint8(a)
        vals.append(delta_e_2000(srgb_to_lab(a.astype(np.float64) / 255.0),
                                 srgb_to_lab(b.astype(np.float64) / 255.0)).ravel())
    v = np.concatenate(vals)
    return ImageDeltaE(float(v.mean()), float(np.percentile(v, 95)), len(images), step)


__all__ = [
    "IMAGE_DE_SAMPLE",
    "CameraRecord",
    "EmulationRecord",
    "ErrorProfile",
    "ImageDeltaE",
    "case_chart",
    "chart_error_profile",
    "image_delta_e",
]
