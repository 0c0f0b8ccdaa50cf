"""Read JPEGs as sRGB code values and write them back with the original encoder settings.

SAFE-COLOR writes every transformed image "as JPEG with the ORIGINAL image's quantization tables
(and its chroma subsampling), so that re-encoding itself changes as little as possible"; ΔE = 0
is the same decode + re-encode with no transform. This module does exactly that with Pillow
(libjpeg): :func:`read_jpeg` returns the pixels and a :class:`JpegSettings` record,
:func:`encode_jpeg` re-encodes with those settings.

Documented rules for the awkward cases of COCO val2017:

* **ICC profiles** (493 of the 1000 shared images carry one: sRGB, Adobe RGB, camera profiles,
  one ProPhoto). The pixel values are taken as sRGB code values *as stored*; the profile is not
  applied. This is what the detectors' own loaders do (OpenCV ignores ICC profiles), so the
  detector sees the same numbers in training, validation and here; the transforms are defined on
  sRGB. The profile bytes are copied unchanged into the output, so the output is tagged like the
  original and a colour-managed viewer shows original and output alike.
* **Grayscale JPEGs** (single channel; 4 of the 1000). They are expanded to RGB with R = G = B
  for the transform (as OpenCV's ``imread`` and the detectors do) and written back as
  single-channel grayscale JPEGs with the original luminance table. All ten transforms map
  grey to grey (hue and saturation leave S = 0; brightness, contrast and gamma act per channel;
  pull_mean's chroma stays at the mean's, ~0), so no colour is lost; if a transform does give
  R != G != B, the output takes ITU-R BT.601 luma (Pillow's ``"L"`` conversion) and
  :attr:`JpegSettings.mode` tells the caller the image was grayscale.
* CMYK or other modes raise :class:`~fidelity.core.errors.InputFileError`.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.record import record

#: Pillow ``subsampling`` codes -> names.
SUBSAMPLING_NAMES: dict[int, str] = {0: "4:4:4", 1: "4:2:2", 2: "4:2:0", -1: "unknown"}


@record
class JpegSettings:
    """Encoder settings of an original JPEG, reused when writing its transformed copy."""

    mode: str  # "RGB" or "L"
    qtables: tuple[tuple[int, ...], ...]
    subsampling: int  # Pillow code: 0 = 4:4:4, 1 = 4:2:2, 2 = 4:2:0
    icc_profile: bytes | None

    def save_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``PIL.Image.save(..., "JPEG", **kwargs)``."""
        kw: dict[str, Any] = {"qtables": [list(t) for t in self.qtables]}
        if self.mode == "RGB" and self.subsampling >= 0:
            kw["subsampling"] = self.subsampling
        if self.icc_profile:
            kw["icc_profile"] = self.icc_profile
        return kw


def _settings(im: Any, source: str) -> JpegSettings:
    from PIL import JpegImagePlugin

    if im.format != "JPEG":
        raise InputFileError(f"{source}: not a JPEG image (format {im.format})")
    if im.mode not in ("RGB", "L"):
        raise InputFileError(f"{source}: JPEG mode {im.mode} is not supported (RGB or L only)")
    q = getattr(im, "quantization", None)
    if not q:
        raise InputFileError(f"{source}: JPEG has no quantization tables")
    tables = tuple(tuple(int(v) for v in q[k]) for k in sorted(q))
    sampling = JpegImagePlugin.get_sampling(im) if im.mode == "RGB" else -1
    return JpegSettings(im.mode, tables, int(sampling), im.info.get("icc_profile"))


def decode_jpeg(data: bytes, source: str = "<bytes>") -> tuple[np.ndarray, JpegSettings]:
    """Decode JPEG bytes into (H, W, 3) uint8 sRGB code values and the encoder settings."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as im:
            settings = _settings(im, source)
            im.load()
            arr = np.asarray(im)
    except UnidentifiedImageError as exc:
        raise InputFileError(f"{source}: not an image file (no known image header)") from exc
    except Image.DecompressionBombError as exc:  # more pixels than Pillow's limit
        raise InputFileError(f"{source}: refused: {exc}") from exc
    except OSError as exc:  # truncated or corrupt data
        raise InputFileError(f"{source}: cannot decode JPEG: {exc}") from exc
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    return np.ascontiguousarray(arr), settings


def read_jpeg(path: str | os.PathLike[str]) -> tuple[np.ndarray, JpegSettings]:
    """Read a JPEG file; see :func:`decode_jpeg`. The file is only read, never modified."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read image: {exc}") from exc
    return decode_jpeg(data, str(p))


def encode_jpeg(rgb: np.ndarray, settings: JpegSettings) -> bytes:
    """Encode (H, W, 3) uint8 RGB with the original's tables, subsampling and ICC profile.

    Grayscale originals (``settings.mode == "L"``) are written as one-channel JPEGs (see module
    docstring for the rule).
    """
    from PIL import Image

    a = np.asarray(rgb)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3) uint8, got {a.shape} {a.dtype}")
    if settings.mode == "L":
        if np.array_equal(a[..., 0], a[..., 1]) and np.array_equal(a[..., 0], a[..., 2]):
            im = Image.fromarray(np.ascontiguousarray(a[..., 0]), "L")
        else:
            im = Image.fromarray(a, "RGB").convert("L")
    else:
        im = Image.fromarray(a, "RGB")
    buf = io.BytesIO()
    im.save(buf, "JPEG", **settings.save_kwargs())
    return buf.getvalue()


def roundtrip_jpeg(rgb: np.ndarray, settings: JpegSettings) -> np.ndarray:
    """Encode with :func:`encode_jpeg` and decode again: what a detector reads from the file."""
    return decode_jpeg(encode_jpeg(rgb, settings))[0]
