"""Several frames of one recording or video (``audit --frames``, ``gate --frames``): the
temporal noise separated from the fixed-pattern noise on the chart's neutral patches, as EMVA
1288 Release 4.0 does it (:func:`fidelity.measure.noise.temporal_and_fixed_pattern`).

The frames are stacked only where the chart has not moved between them: the located corner
patch centres of every frame agree with the first frame's within :data:`MAX_CORNER_SHIFT`
pixels. Each measured frame is read again (a video frame by seeking, a recording's message by
its index) and each neutral patch's sampling window of the first frame (its largest
rectangle of whole pixels, so that the row and column parts are defined) is taken in linear
light as the one-frame noise measurement takes it
(:func:`fidelity.measure.pixels.window_linear`): the luminance
``Y = 0.2126 R + 0.7152 G + 0.0722 B`` of linear sRGB. Per patch: the temporal and the
fixed-pattern standard deviation; at the 18 % grey patch the temporal-only SNR; over the
neutral patches the photon-transfer line fitted on the temporal variances (no fixed-pattern
noise in it, unlike the one-frame estimate).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from fidelity.chart.locate import PatchWindow
from fidelity.chart.read import ReadOptions, read_input
from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import Reference
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import display_path, finite_or_none
from fidelity.core.record import record
from fidelity.measure.chartnoise import grey_index
from fidelity.measure.noise import (
    LUMINANCE_WEIGHTS,
    FrameNoise,
    PhotonTransfer,
    RefusedFit,
    photon_transfer,
    temporal_and_fixed_pattern,
)
from fidelity.measure.pixels import window_linear
from fidelity.pipeline.records import ChartReport, ImageSource

#: Largest shift (pixels) of a located corner patch centre from the first frame's at which the
#: chart counts as not moved and the frames are stacked.
MAX_CORNER_SHIFT = 0.25
#: Where the method is named.
METHOD = ("EMVA 1288 4.0: temporal variance = mean over pixels of each pixel's variance over "
          "the frames (frame-mean offsets removed); fixed-pattern variance = spatial variance "
          "of the mean frame less temporal / L; on each neutral patch's largest whole-pixel "
          "rectangle of the first frame's window, luminance Y of linear sRGB")


@record
class PatchFramesNoise:
    """One neutral patch's noise over the frames.

    Attributes
    ----------
    patch
        The patch's name.
    noise
        Its luminance's temporal and fixed-pattern noise
        (:class:`fidelity.measure.noise.FrameNoise`; linear values, full scale 1).
    snr
        Temporal-only SNR, ``mean / temporal_noise`` (None: no temporal noise).
    """

    patch: str
    noise: FrameNoise
    snr: float | None

    def to_json(self) -> dict[str, Any]:
        """The patch's JSON object: its name, the FrameNoise fields and the SNR."""
        out = {"patch": self.patch, **self.noise.to_json(), "snr": finite_or_none(self.snr)}
        del out["method"]  # the stack's own
        return out


@record
class FramesNoise:
    """The temporal and fixed-pattern noise of one recording's frames (:func:`frames_noise`).

    Attributes
    ----------
    recording
        The recording or video, as shown.
    frames
        The frames measured (stacked, or considered for stacking).
    stacked
        Whether they were stacked; if not, ``reason`` says why.
    reason
        Why not (the chart moved, fewer than 2 measured frames, a patch too small); None when
        stacked.
    corner_shift
        The largest shift (pixels) of a located corner centre from the first frame's; None with
        fewer than 2 measured frames.
    patches
        Per neutral patch, in chart order (empty when not stacked).
    grey_patch
        The 18 % grey patch (:func:`fidelity.measure.chartnoise.grey_index`); None when not
        stacked.
    transfer
        The photon-transfer line on the temporal variances
        (:func:`fidelity.measure.noise.photon_transfer`); None where not stacked or refused.
    transfer_refusal
        Why the line was refused (:class:`fidelity.measure.noise.RefusedFit`'s message).
    linearisation
        How the pixels were made linear.
    method
        :data:`METHOD`.
    """

    recording: str
    frames: tuple[int, ...]
    stacked: bool
    reason: str | None
    corner_shift: float | None
    patches: tuple[PatchFramesNoise, ...] = ()
    grey_patch: str | None = None
    transfer: PhotonTransfer | None = None
    transfer_refusal: str | None = None
    linearisation: str = ""
    method: str = METHOD

    @property
    def grey(self) -> PatchFramesNoise | None:
        """The grey patch's noise (None when not stacked)."""
        return next((p for p in self.patches if p.patch == self.grey_patch), None)

    def summary(self) -> str:
        """One line for the frames summary."""
        shown = self.recording
        if not self.stacked:
            return f"{shown}: noise over the frames not measured: {self.reason}"
        g = self.grey
        assert g is not None
        snr = "" if g.snr is None else f", temporal SNR {g.snr:.1f} ({20 * math.log10(g.snr):.1f} dB)"
        return (f"{shown}: noise over {g.noise.frames} frames at {g.patch} (linear Y): temporal "
                f"σ {g.noise.temporal_noise:.5f} ± {_u_sigma(g.noise):.5f}, "
                f"{fixed_pattern_words(g.noise)}{snr} (EMVA 1288 4.0)")

    def to_json(self) -> dict[str, Any]:
        """The ``frames_noise`` JSON object (``fidelity/data/schemas/frames.schema.json``)."""
        return {
            "recording": self.recording, "frames": list(self.frames), "stacked": self.stacked,
            "reason": self.reason, "corner_shift_px": finite_or_none(self.corner_shift),
            "max_corner_shift_px": MAX_CORNER_SHIFT,
            "patches": [p.to_json() for p in self.patches], "grey_patch": self.grey_patch,
            "transfer": None if self.transfer is None else self.transfer.to_json(),
            "transfer_refusal": self.transfer_refusal,
            "linearisation": self.linearisation, "method": self.method,
        }


def fixed_pattern_words(n: FrameNoise) -> str:
    """The fixed-pattern σ as printed: ``fixed-pattern σ S ± U`` where its variance exceeds
    twice its uncertainty, else its upper bound ``fixed-pattern σ < B (0 within 2u)`` with
    ``B = sqrt(max(s^2, 0) + 2 u(s^2))``."""
    s2, u = n.spatial_variance, n.u_spatial_variance
    if s2 > 2.0 * u:
        return (f"fixed-pattern σ {n.fixed_pattern_noise:.5f} ± "
                f"{u / (2.0 * n.fixed_pattern_noise):.5f}")
    return f"fixed-pattern σ < {math.sqrt(max(s2, 0.0) + 2.0 * u):.5f} (0 within 2u)"


def _u_sigma(n: FrameNoise) -> float:
    """Standard uncertainty of the temporal σ, ``u(σ²) / (2σ)``."""
    return n.u_temporal_variance / (2.0 * n.temporal_noise) if n.temporal_noise > 0 else 0.0


def whole_rectangle(window: PatchWindow) -> tuple[int, int, int, int]:
    """The largest rectangle (found greedily) of whole pixels in a patch window's mask:
    ``(y0, y1, x0, x1)`` image rows ``y0 .. y1 - 1`` and columns ``x0 .. x1 - 1``; the whole box
    for a window square to the pixels. Shrinks the box by the edge row or column with the most
    pixels outside the mask until none is."""
    mask = np.asarray(window.mask, bool)
    r0, r1, c0, c1 = 0, mask.shape[0], 0, mask.shape[1]
    while r1 > r0 and c1 > c0:
        sub = mask[r0:r1, c0:c1]
        if sub.all():
            break
        edges = {"top": int((~sub[0]).sum()), "bottom": int((~sub[-1]).sum()),
                 "left": int((~sub[:, 0]).sum()), "right": int((~sub[:, -1]).sum())}
        worst = max(edges, key=lambda k: edges[k])
        if worst == "top":
            r0 += 1
        elif worst == "bottom":
            r1 -= 1
        elif worst == "left":
            c0 += 1
        else:
            c1 -= 1
    return window.y0 + r0, window.y0 + r1, window.x0 + c0, window.x0 + c1


def corner_shift(reports: Sequence[ChartReport]) -> float:
    """The largest distance (pixels) of any frame's located corner patch centres from the first
    frame's."""
    first = np.asarray(reports[0].source.corners, np.float64)  # type: ignore[union-attr]
    return max(float(np.max(np.hypot(*(np.asarray(r.source.corners, np.float64)  # type: ignore[union-attr]
                                       - first).T))) for r in reports)


def frames_noise(path: str | os.PathLike[str], frames: Sequence[int],
                 reports: Sequence[ChartReport | None], read: ReadOptions,
                 reference: Reference) -> FramesNoise:
    """The temporal and fixed-pattern noise of the measured frames of one recording.

    Parameters
    ----------
    path
        The recording or video.
    frames
        Its frames audited or gated, one per report.
    reports
        Each frame's chart report (None: not measured; left out).
    read
        How they were read (:class:`~fidelity.chart.read.ReadOptions`; its frame is replaced).
    reference
        The reference chart (its neutral patches and names).

    Returns
    -------
    FramesNoise
        Stacked (per neutral patch, temporal and fixed-pattern σ in linear light, full scale 1;
        the grey patch's temporal SNR; the photon-transfer line on the temporal variances), or
        not stacked with the reason: fewer than 2 measured frames, the chart moved more than
        :data:`MAX_CORNER_SHIFT` pixels, a neutral patch window under 2 x 2 whole pixels.

    Raises
    ------
    fidelity.core.errors.InputFileError
        A frame that was read once cannot be read again.
    """
    shown = display_path(path)
    got = [(k, r) for k, r in zip(frames, reports, strict=True) if r is not None]
    ks = tuple(k for k, _ in got)
    if len(got) < 2:
        return FramesNoise(shown, ks, False, f"{len(got)} measured frame(s); stacking needs 2",
                           None)
    reps = [r for _, r in got]
    if not all(isinstance(r.source, ImageSource) for r in reps):
        return FramesNoise(shown, ks, False, "not image frames", None)
    shift = corner_shift(reps)
    if shift > MAX_CORNER_SHIFT:
        return FramesNoise(shown, ks, False,
                           f"the chart moved between the frames (a corner by {shift:.2f} px; "
                           f"stacked within {MAX_CORNER_SHIFT} px), so they were not stacked",
                           shift)
    first = reps[0].source
    assert isinstance(first, ImageSource)
    neutral = list(reference.neutral_indices)
    names = reference.patch_names
    boxes = [whole_rectangle(first.location.windows[k]) for k in neutral]
    if any(y1 - y0 < 2 or x1 - x0 < 2 for y0, y1, x0, x1 in boxes):
        return FramesNoise(shown, ks, False, "a neutral patch window has under 2 x 2 whole "
                           "pixels", shift)
    stacks: list[list[np.ndarray]] = [[] for _ in neutral]
    how = ""
    for k in ks:
        img, _ = read_input(path, replace(read, frame=k, time=None), native=True)
        enc = read.encoding or img.encoding
        colourspace = (read.colourspace if read.colourspace is not None
                       else img.chromaticities or "sRGB")
        to_srgb = cm.matrix_rgb_to_linear_srgb(colourspace)
        for j, (y0, y1, x0, x1) in enumerate(boxes):
            box = img.pixels[y0:y1, x0:x1]
            lin, how = window_linear(box, enc, to_srgb)
            stacks[j].append(lin @ np.asarray(LUMINANCE_WEIGHTS))
    patches = []
    for j, k in enumerate(neutral):
        fn = temporal_and_fixed_pattern(np.stack(stacks[j]))
        snr = fn.mean / fn.temporal_noise if fn.temporal_noise > 0 else None
        patches.append(PatchFramesNoise(names[k], fn, snr))
    ref_y = cm.lab_to_xyz(np.asarray(reference.lab, np.float64))[:, 1]
    grey = names[grey_index(names, neutral, ref_y)]
    g = next(p for p in patches if p.patch == grey)
    transfer: PhotonTransfer | None = None
    refusal: str | None = None
    try:
        transfer = photon_transfer(
            [p.noise.mean for p in patches], [p.noise.temporal_variance for p in patches],
            [p.noise.rows * p.noise.columns * (p.noise.frames - 1) + 1 for p in patches],
            grey_mean=g.noise.mean)
    except (RefusedFit, FidelityError) as exc:
        refusal = str(exc)
    return FramesNoise(shown, ks, True, None, shift, tuple(patches), grey, transfer, refusal,
                       how)


__all__ = ["MAX_CORNER_SHIFT", "METHOD", "FramesNoise", "PatchFramesNoise", "corner_shift",
           "fixed_pattern_words", "frames_noise", "whole_rectangle"]
