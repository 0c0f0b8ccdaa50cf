"""Transformed copies of an image set: one subset per (transform, ΔE target), as SAFE-COLOR made.

Every image is read as sRGB code values (:mod:`fidelity.jpeg`), transformed with the parameter
calibrated on the chart for that (transform, ΔE), rounded to 8 bit and written back as JPEG with
the original's quantization tables, chroma subsampling and ICC profile. ΔE = 0 is the baseline:
decode and re-encode only.

Fast path (:class:`PixelMap`). Images are 8-bit, so for a fixed (transform, parameter) every
transform except ``pull_mean`` is a pure per-pixel function of the RGB triple:

* brightness, contrast, gamma act on each channel alone: a 256-entry lookup table per channel,
  built by evaluating :func:`fidelity.transforms.apply_transform` on the 256 code values.
* saturation and hue mix channels: a 256^3-entry table (48 MiB of uint8) built once per
  (transform, parameter) by evaluating the same reference function on all 16,777,216 triples.
* ``pull_mean`` depends on the image's mean Lab, so it runs the reference function per image.

The tables are built from the reference function itself, evaluated in float64 on ``code/255``,
then rounded exactly like the slow path (:func:`to_uint8`), so the fast path equals the
reference bit for bit (the tests check this on real images).

Rounding rule: ``uint8 = rint(clip(x, 0, 1) * 255)`` (round half to even).
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.errors import InputFileError, InvalidValueError

#: Transforms that act on each channel separately with the same 1-D function.
CHANNELWISE: frozenset[str] = frozenset({
    "brightness-dec", "brightness-inc", "contrast-dec", "contrast-inc", "gamma-dec", "gamma-inc",
})
#: Transforms that need the whole image (per-image statistics).
PER_IMAGE: frozenset[str] = frozenset({"pull_mean"})

BASELINE = "baseline"


def to_uint8(x: np.ndarray) -> np.ndarray:
    """Round [0, 1] floats to 8-bit code values: ``rint(clip(x, 0, 1) * 255)``."""
    return np.rint(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


def reference_transform(rgb8: np.ndarray, name: str, param: float) -> np.ndarray:
    """The slow reference: float64 ``apply_transform(rgb8 / 255, name, param)`` rounded to 8 bit."""
    from fidelity.transforms import apply_transform

    x = np.asarray(rgb8, dtype=np.float64) / 255.0
    return to_uint8(apply_transform(x, name, param))


def _all_triples(start: int, stop: int) -> np.ndarray:
    idx = np.arange(start, stop, dtype=np.uint32)
    rgb = np.empty((stop - start, 3), dtype=np.float64)
    rgb[:, 0] = (idx >> 16) & 255
    rgb[:, 1] = (idx >> 8) & 255
    rgb[:, 2] = idx & 255
    return rgb / 255.0


@dataclass
class PixelMap:
    """A fast, exact 8-bit implementation of one (transform, parameter)."""

    name: str
    param: float | None
    kind: str  # "identity", "channel", "cube", "image"
    lut: np.ndarray | None = None
    build_seconds: float = 0.0
    lut16: np.ndarray | None = None

    @classmethod
    def build(cls, name: str, param: float | None, chunk: int = 1 << 20) -> PixelMap:
        """Build the table for ``name`` at ``param`` (``name == "baseline"``: identity)."""
        t0 = time.perf_counter()
        if name == BASELINE:
            return cls(name, None, "identity")
        from fidelity.transforms import TRANSFORMS, apply_transform

        if name not in TRANSFORMS:
            from fidelity.errors import unknown_name

            raise unknown_name("transform", name, list(TRANSFORMS) + [BASELINE])
        if param is None or not np.isfinite(param):
            raise InvalidValueError(f"transform {name}: parameter {param!r} is not a number")
        if name in PER_IMAGE:
            return cls(name, float(param), "image")
        if name in CHANNELWISE:
            v = np.repeat((np.arange(256, dtype=np.float64) / 255.0)[:, None], 3, axis=1)
            out = to_uint8(apply_transform(v, name, float(param)))
            if not (np.array_equal(out[:, 0], out[:, 1]) and np.array_equal(out[:, 0], out[:, 2])):
                raise InvalidValueError(f"transform {name} is not channel-wise")
            lut8 = np.ascontiguousarray(out[:, 0])
            # pair table: one uint16 lookup maps two neighbouring bytes at once
            pair = np.arange(1 << 16, dtype=np.uint16).view(np.uint8).reshape(-1, 2)
            lut16 = np.ascontiguousarray(lut8[pair]).view(np.uint16).ravel()
            pm = cls(name, float(param), "channel", lut8, time.perf_counter() - t0)
            pm.lut16 = lut16
            return pm
        lut = np.empty((1 << 24, 3), dtype=np.uint8)
        for s in range(0, 1 << 24, chunk):
            e = min(s + chunk, 1 << 24)
            lut[s:e] = to_uint8(apply_transform(_all_triples(s, e), name, float(param)))
        return cls(name, float(param), "cube", lut, time.perf_counter() - t0)

    def __call__(self, rgb8: np.ndarray) -> np.ndarray:
        """Apply to an (H, W, 3) uint8 image; returns a new uint8 image."""
        a = np.asarray(rgb8)
        if a.dtype != np.uint8 or a.shape[-1] != 3:
            raise InvalidValueError(f"image must be (..., 3) uint8, got {a.shape} {a.dtype}")
        if self.kind == "identity":
            return a.copy()
        if self.kind == "channel":
            assert self.lut is not None
            if self.lut16 is not None and a.flags.c_contiguous and a.size % 2 == 0:
                flat = a.reshape(-1).view(np.uint16)
                return np.take(self.lut16, flat).view(np.uint8).reshape(a.shape)
            return np.take(self.lut, a)
        if self.kind == "cube":
            assert self.lut is not None
            idx = a[..., 0].astype(np.uint32)
            idx <<= 8
            idx |= a[..., 1]
            idx <<= 8
            idx |= a[..., 2]
            return np.take(self.lut, idx, axis=0)
        assert self.param is not None
        if self.name == "pull_mean":
            if self.lut is None:
                self.lut = np.empty(1 << 24, dtype=np.int32)  # colour -> index scratch table
            return pull_mean_uint8(a, self.param, self.lut)
        return reference_transform(a, self.name, self.param)


def pull_mean_uint8(rgb8: np.ndarray, alpha: float, scratch: np.ndarray | None = None
                    ) -> np.ndarray:
    """Exact 8-bit ``pull_mean``, with the Lab <-> sRGB work done once per distinct colour.

    Same arithmetic per colour as :func:`fidelity.transforms.pull_mean` on ``rgb8 / 255`` in
    float64 (sRGB decoding through a 256-entry table of the same function's values), on the
    distinct colours only (a natural 640x480 image has ~40k of ~300k pixels). The mean Lab is
    the count-weighted sum over distinct colours divided by the pixel count: the same number as
    the reference's sum over pixels up to the order of additions (a few ulp), which changed no
    8-bit code on 300 COCO images at three α (tests/test_dataset.py checks 20 of them on every
    run). ``scratch``: optional int32 array of 2^24 entries reused as the colour -> index table.
    """
    from fidelity.colorimetry import lab_to_srgb, linear_srgb_to_xyz, xyz_to_lab

    a = np.asarray(rgb8)
    packed = a[..., 0].astype(np.uint32)
    packed <<= 8
    packed |= a[..., 1]
    packed <<= 8
    packed |= a[..., 2]
    packed = packed.ravel()
    srt = np.sort(packed)
    first = np.empty(srt.size, dtype=bool)
    first[:1] = True
    np.not_equal(srt[1:], srt[:-1], out=first[1:])
    starts = np.flatnonzero(first)
    uniq = srt[starts]
    counts = np.diff(starts, append=srt.size).astype(np.float64)
    table = scratch if scratch is not None else np.empty(1 << 24, dtype=np.int32)
    table[uniq] = np.arange(uniq.size, dtype=np.int32)
    inverse = table[packed]
    codes = np.empty((uniq.size, 3), dtype=np.uint8)
    codes[:, 0] = uniq >> 16
    codes[:, 1] = uniq >> 8
    codes[:, 2] = uniq
    lab_u = xyz_to_lab(linear_srgb_to_xyz(_srgb_linear_table()[codes]))
    mean = (counts @ lab_u) / srt.size
    pulled = mean + np.float64(alpha) * (lab_u - mean)
    out_u = to_uint8(lab_to_srgb(pulled))
    return np.take(out_u, inverse, axis=0).reshape(a.shape)


@functools.cache
def _srgb_linear_table() -> np.ndarray:
    """Linear values of the 256 sRGB code values (:func:`fidelity.colorimetry.linearize_srgb`)."""
    from fidelity.colorimetry import linearize_srgb

    table = linearize_srgb(np.arange(256, dtype=np.float64) / 255.0)
    table.flags.writeable = False
    return table


# --------------------------------------------------------------------------------------------
# Calibrated parameters


def calibrated_param(transform: str, target: float) -> tuple[float | None, str | None]:
    """Parameter of ``transform`` calibrated for chart ΔE ``target`` (shipped calibration table).

    Returns ``(param, None)`` or ``(None, reason)`` when the target is unreachable or not in the
    table. ``target == 0`` is the baseline: ``(None, None)``.
    """
    if target == 0:
        return None, None
    from fidelity.calibration import calibrate_transform, load_calibration_table

    try:
        table = load_calibration_table()
        p = table.param(transform, target)
        if p is not None:
            return float(p), None
    except Exception:  # noqa: BLE001 - fall back to calibrating on the spot
        p = None
    entry = calibrate_transform(transform, float(target))
    if not entry.reachable or entry.param is None:
        return None, (f"{transform} cannot reach chart ΔE {target:g} "
                      f"(reaches at most {entry.delta_e:.2f} in its range)")
    return float(entry.param), None


# --------------------------------------------------------------------------------------------
# Writing datasets


def subset_name(transform: str, target: float) -> str:
    """Folder name of one subset: ``baseline`` or ``<transform>_de<target>``."""
    return BASELINE if target == 0 else f"{transform}_de{target:g}"


def list_images(folder: str | os.PathLike[str]) -> list[Path]:
    """JPEG files in ``folder`` (sorted by name)."""
    d = Path(folder)
    if not d.is_dir():
        raise InputFileError(f"{d}: image folder does not exist")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in (".jpg", ".jpeg"))
    if not files:
        raise InputFileError(f"{d}: no .jpg/.jpeg images in the folder")
    return files


#: Per-process cache of the last built table, so that a pool worker builds a 256^3 table once
#: per subset and not once per image (each worker process has its own copy).
_WORKER_MAP: dict[tuple[str, float | None], PixelMap] = {}


def _write_one(args: tuple[str, str, str, float | None]) -> str:
    from fidelity.fileio import write_bytes_atomic
    from fidelity.jpeg import encode_jpeg, read_jpeg

    src, dst, name, param = args
    key = (name, param)
    pm = _WORKER_MAP.get(key)
    if pm is None:
        _WORKER_MAP.clear()
        pm = _WORKER_MAP[key] = PixelMap.build(name, param)
    rgb, settings = read_jpeg(src)
    write_bytes_atomic(dst, encode_jpeg(pm(rgb), settings))
    return dst


def write_transformed_dataset(images: Sequence[Path], out_dir: str | os.PathLike[str],
                              transform: str, target: float, *, param: float | None = None,
                              workers: int = 1, progress: bool = True) -> dict[str, Any]:
    """Write one subset: every image transformed for (``transform``, ΔE ``target``).

    ``param`` overrides the calibrated parameter. Existing outputs are skipped (resumable);
    each file is written atomically; inputs are never overwritten. Returns a summary dict.
    """
    out = Path(out_dir)
    name = transform
    if target == 0:
        name, param = BASELINE, None
    elif param is None:
        param, reason = calibrated_param(transform, target)
        if param is None:
            from fidelity.errors import UnreachableTargetError

            raise UnreachableTargetError(reason or f"{transform} at ΔE {target:g} unreachable")
    sub = out / subset_name(transform, target)
    srcs = {p.resolve() for p in images}
    jobs = []
    for p in images:
        dst = sub / p.name
        if dst.resolve() in srcs:
            raise InputFileError(f"{dst}: output would overwrite an input image")
        if not dst.exists():
            jobs.append((str(p), str(dst), name, param))
    sub.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    _run_jobs(jobs, workers, progress, f"{subset_name(transform, target)}")
    return {"subset": sub.name, "transform": name, "target": target, "param": param,
            "written": len(jobs), "skipped": len(images) - len(jobs),
            "seconds": time.perf_counter() - t0}


def _run_jobs(jobs: list[tuple[str, str, str, float | None]], workers: int, progress: bool,
              desc: str) -> None:
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), desc=desc, unit="img", disable=not progress or not jobs)
    try:
        if workers <= 1 or len(jobs) < 2:
            for j in jobs:
                _write_one(j)
                bar.update()
        else:
            with ProcessPoolExecutor(max_workers=workers) as ex:
                for _ in ex.map(_write_one, jobs, chunksize=8):
                    bar.update()
    finally:
        bar.close()


def write_grid(images: Sequence[Path], out_dir: str | os.PathLike[str],
               transforms: Iterable[str], targets: Iterable[float], *, workers: int = 1,
               progress: bool = True,
               on_skip: Callable[[str, float, str], None] | None = None) -> list[dict[str, Any]]:
    """Write every (transform, target) subset; unreachable cells are reported, not written."""
    from fidelity.errors import UnreachableTargetError

    results = []
    done_baseline = False
    for t in transforms:
        for e in targets:
            if e == 0:
                if done_baseline:
                    continue
                done_baseline = True
            try:
                results.append(write_transformed_dataset(images, out_dir, t, e, workers=workers,
                                                         progress=progress))
            except UnreachableTargetError as exc:
                results.append({"subset": subset_name(t, e), "transform": t, "target": e,
                                "skipped_reason": str(exc)})
                if on_skip:
                    on_skip(t, e, str(exc))
    return results
