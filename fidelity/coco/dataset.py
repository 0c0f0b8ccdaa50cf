"""Transformed copies of an image set: one subset per (transform, ΔE target), as SAFE-COLOR made.

Every image is read as sRGB code values (:mod:`fidelity.coco.jpeg`), transformed with the parameter
calibrated on the chart for that (transform, ΔE), rounded to 8 bit and written back as JPEG with
the original's quantization tables, chroma subsampling and ICC profile. ΔE = 0 is the baseline:
decode and re-encode only.

Fast path (:class:`PixelMap`). Images are 8-bit, so for a fixed (transform, parameter) every
transform except ``pull_mean`` is a pure per-pixel function of the RGB triple:

* brightness, contrast, gamma act on each channel alone: a 256-entry lookup table per channel,
  built by evaluating :func:`fidelity.prediction.transforms.apply_transform` on the 256 code values.
* saturation and hue mix channels: a 256^3-entry table (48 MiB of uint8) built once per
  (transform, parameter) by evaluating the same reference function on all 16,777,216 triples.
* ``pull_mean`` depends on the image's mean Lab, so it runs per image, on the image's distinct
  colours (:func:`pull_mean_uint8`).

The tables are built from the reference function itself, evaluated in float64 on ``code/255``,
then rounded exactly like the slow path (:func:`to_uint8`), so the fast path equals the
reference bit for bit (the tests check this on real images).

Rounding rule: ``uint8 = rint(clip(x, 0, 1) * 255)`` (round half to even).
"""

from __future__ import annotations

import functools
import importlib
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor  # noqa: TID253 (the pool of the dataset)
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.coco.jpeg import encode_jpeg, read_jpeg
from fidelity.colour.colorimetry import (
    CIE_EPSILON,
    CIE_KAPPA,
    MATRIX_LINEAR_SRGB_TO_XYZ,
    MATRIX_XYZ_TO_LINEAR_SRGB,
    WHITEPOINT_D65_XYZ,
    linearize_srgb,
)
from fidelity.core.errors import (
    InputFileError,
    InvalidValueError,
    UnreachableTargetError,
    unknown_name,
)
from fidelity.core.fileio import remove_stale_temporaries, write_bytes_atomic
from fidelity.core.record import record
from fidelity.prediction.calibration import calibrate_transform, load_calibration_table
from fidelity.prediction.transforms import TRANSFORMS, apply_transform

#: Transforms that act on each channel separately with the same 1-D function.
CHANNELWISE: frozenset[str] = frozenset({
    "brightness-dec", "brightness-inc", "contrast-dec", "contrast-inc", "gamma-dec", "gamma-inc",
})
#: Transforms that need the whole image (per-image statistics).
PER_IMAGE: frozenset[str] = frozenset({"pull_mean"})

BASELINE = "baseline"


def to_uint8(x: np.ndarray) -> np.ndarray:
    """Round [0, 1] floats to 8-bit code values: ``rint(clip(x, 0, 1) * 255)``."""
    out: np.ndarray = np.rint(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)
    return out


def reference_transform(rgb8: np.ndarray, name: str, param: float) -> np.ndarray:
    """The slow reference: float64 ``apply_transform(rgb8 / 255, name, param)`` rounded to 8 bit."""
    x = np.asarray(rgb8, dtype=np.float64) / 255.0
    return to_uint8(apply_transform(x, name, param))


def all_triples(start: int, stop: int) -> np.ndarray:
    """The 8-bit RGB triples with 24-bit codes ``start`` to ``stop - 1`` as floats in [0, 1].

    Code ``i`` is ``(r << 16) | (g << 8) | b``; row ``i - start`` is ``(r, g, b) / 255``:
    the inputs of a 16.7-million-entry 8-bit lookup table, a chunk at a time.
    """
    return code_triples(np.arange(start, stop, dtype=np.uint32))


def code_triples(codes: np.ndarray) -> np.ndarray:
    """The 8-bit RGB triples of the 24-bit codes ``codes`` ((N,), :func:`colour_codes`) as
    (N, 3) floats in [0, 1], computed as :func:`all_triples` computes its rows."""
    idx = np.asarray(codes, dtype=np.uint32).reshape(-1)
    rgb = np.empty((idx.size, 3), dtype=np.float64)
    rgb[:, 0] = (idx >> 16) & 255
    rgb[:, 1] = (idx >> 8) & 255
    rgb[:, 2] = idx & 255
    out: np.ndarray = rgb / 255.0
    return out


def colour_codes(rgb8: np.ndarray) -> np.ndarray:
    """The 24-bit code ``(r << 16) | (g << 8) | b`` (uint32) of each pixel of (..., 3) uint8."""
    a = np.asarray(rgb8)
    idx: np.ndarray = a[..., 0].astype(np.uint32)
    idx <<= 8
    idx |= a[..., 1]
    idx <<= 8
    idx |= a[..., 2]
    return idx


@dataclass
class PixelMap:
    """A fast, exact 8-bit implementation of one (transform, parameter)."""

    name: str
    param: float | None
    kind: str  # "identity", "channel", "cube", "codes", "direct", "image"
    lut: np.ndarray | None = None
    build_seconds: float = 0.0
    lut16: np.ndarray | None = None
    workspace: PullMeanWorkspace | None = None
    kernel: str = "auto"
    codes: np.ndarray | None = None

    @classmethod
    def of_codes(cls, name: str, codes: np.ndarray, values: np.ndarray) -> PixelMap:
        """A mapping known on some colours only: the sorted, distinct 24-bit codes ``codes``
        (``(r << 16) | (g << 8) | b``, uint32, (N,)) to ``values`` (N, 3) uint8; an image with
        any other colour is refused. The table of a run on a few images: their colours are a
        small part of the 2^24 a ``"cube"`` holds (:func:`colour_codes`)."""
        c = np.ascontiguousarray(codes, dtype=np.uint32)
        v = np.ascontiguousarray(values, dtype=np.uint8)
        if c.ndim != 1 or v.shape != (c.size, 3) or bool(np.any(c[1:] <= c[:-1])):
            raise InvalidValueError(f"colour table of {name}: codes must be sorted and distinct "
                                    f"(N,) with (N, 3) values, got {c.shape} and {v.shape}")
        return cls(name, None, "codes", v, codes=c)

    @classmethod
    def build(cls, name: str, param: float | None, chunk: int = 1 << 20, direct: bool = False
              ) -> PixelMap:
        """Build the table for ``name`` at ``param`` (``name == "baseline"``: identity).

        ``direct``: a transform that needs the 2^24-entry table (48 MiB, seconds to build) maps
        each image on its distinct colours instead (kind ``"direct"``: the same codes), for a
        run on a few images."""
        t0 = time.perf_counter()
        if name == BASELINE:
            return cls(name, None, "identity")

        if name not in TRANSFORMS:
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
        if direct:
            return cls(name, float(param), "direct")
        lut = np.empty((1 << 24, 3), dtype=np.uint8)
        for s in range(0, 1 << 24, chunk):
            e = min(s + chunk, 1 << 24)
            lut[s:e] = to_uint8(apply_transform(all_triples(s, e), name, float(param)))
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
            return np.take(self.lut, colour_codes(a), axis=0)
        if self.kind == "codes":
            assert self.lut is not None and self.codes is not None
            idx = colour_codes(a)
            if idx.size == 0:
                return np.empty(a.shape, np.uint8)
            pos = np.searchsorted(self.codes, idx)
            np.minimum(pos, max(self.codes.size - 1, 0), out=pos)
            if self.codes.size == 0 or not np.array_equal(self.codes[pos], idx):
                # an internal error (exit 3): the table was made from other pixels than these
                raise RuntimeError(f"transform {self.name}: the image holds colours its table "
                                   f"was not made for (a table of a run's own images only)")
            return np.take(self.lut, pos, axis=0)
        assert self.param is not None
        if self.kind == "direct":
            codes, inverse = np.unique(colour_codes(a).ravel(), return_inverse=True)
            mapped = to_uint8(apply_transform(code_triples(codes), self.name, self.param))
            out: np.ndarray = mapped[inverse].reshape(a.shape)
            return out
        if self.name == "pull_mean":
            if self.workspace is None:
                self.workspace = PullMeanWorkspace()
            return pull_mean_uint8(a, self.param, self.workspace, self.kernel)
        return reference_transform(a, self.name, self.param)


#: pull_mean kernels: ``"numpy"`` (always available) and ``"numba"`` (the per-colour
#: element-wise steps compiled, when numba is installed: ``pip install fidelity[fast]``).
PULL_MEAN_KERNELS: tuple[str, ...] = ("numpy", "numba")


def pull_mean_kernel(kernel: str = "auto") -> str:
    """The pull_mean kernel that runs: ``"auto"`` picks numba when it imports, else numpy.

    ``$FIDELITY_PULL_MEAN_KERNEL`` (``numpy`` or ``numba``) overrides ``"auto"``.
    """
    if kernel == "auto":
        kernel = os.environ.get("FIDELITY_PULL_MEAN_KERNEL", "auto")
    if kernel == "auto":
        return "numba" if _numba_kernels() is not None else "numpy"
    if kernel not in PULL_MEAN_KERNELS:
        raise unknown_name("pull_mean kernel", kernel, [*PULL_MEAN_KERNELS, "auto"])
    if kernel == "numba" and _numba_kernels() is None:
        raise InvalidValueError("pull_mean kernel 'numba' needs numba (pip install numba)")
    return kernel


#: Fewest images a run writes with pull_mean for the numba kernel to pay for itself. Importing
#: numba and loading its kernels from the disk cache add 1.5-2 s to a run (then inherited by
#: forked workers; ``benchmarks/speed/dataset.py``: 8 COCO photos in 2.67 s with numba forced,
#: 1.17 s without, default workers); the kernel saves about 1.5 ms of CPU per 640x480 photo
#: (``benchmarks/speed/pipeline.py`` on a quiet machine: 2.75 against 4.28 ms; the dataset benchmark's
#: marginal CPU per photo 18.0-18.5 against 19.5-21.2 ms), so about 1000 photos break even.
#: Both kernels give the same bits.
NUMBA_MIN_IMAGES = 1000


def run_kernel(images: int) -> str:
    """The pull_mean kernel for a run writing ``images`` images: numpy for fewer than
    :data:`NUMBA_MIN_IMAGES` (numba is not even imported), else :func:`pull_mean_kernel`'s
    choice; ``$FIDELITY_PULL_MEAN_KERNEL`` decides when set."""
    if images < NUMBA_MIN_IMAGES and not os.environ.get("FIDELITY_PULL_MEAN_KERNEL"):
        return "numpy"
    return pull_mean_kernel("auto")


def pull_mean_uint8(rgb8: np.ndarray, alpha: float,
                    workspace: PullMeanWorkspace | None = None, kernel: str = "auto"
                    ) -> np.ndarray:
    """Exact 8-bit ``pull_mean``, with the Lab <-> sRGB work done once per distinct colour.

    Same arithmetic per colour as :func:`fidelity.prediction.transforms.pull_mean` on
    ``rgb8 / 255`` in float64 (sRGB decoding through a 256-entry table of the same function's
    values), on the distinct colours only (a natural 640x480 image has 40k-180k of ~300k
    pixels); the output codes are equal to the reference's (tests/coco/test_dataset.py).

    The pixels, packed into 24-bit keys, are sorted to find the distinct colours and their
    counts; the mean Lab is the count-weighted sum over distinct colours divided by the pixel
    count (the reference's sum over pixels up to the order of additions, a few ulp, which
    changed no 8-bit code on 1000 COCO images x 3 α); the output codes go back to the pixels
    through a 2^24-entry table. ``kernel`` (:func:`pull_mean_kernel`): ``numpy`` runs the
    per-colour colour science as numpy calls; ``numba`` fuses its element-wise steps into
    compiled loops (same operations, same bits, about 4x faster there).

    ``workspace``: optional :class:`PullMeanWorkspace` reused between images, so that the
    tables and the float planes are not allocated (and page-faulted) for every image.
    Domain: (..., 3) uint8 sRGB codes, α in [0, 1]; range: uint8 codes of the same shape.
    """
    ws = workspace if workspace is not None else PullMeanWorkspace()
    a = np.ascontiguousarray(rgb8)
    if a.dtype != np.uint8 or a.ndim < 1 or a.shape[-1] != 3:
        raise InvalidValueError(f"image must be (..., 3) uint8, got {a.shape} {a.dtype}")
    pixels = a.reshape(-1, 3)
    if pixels.shape[0] == 0:
        return a.copy()
    return ws.pull(pixels, float(alpha), _kernels_for(kernel)).reshape(a.shape)


def _kernels_for(kernel: str) -> _NumbaKernels | None:
    return _numba_kernels() if pull_mean_kernel(kernel) == "numba" else None


class PullMeanWorkspace:
    """Reusable buffers of :func:`pull_mean_uint8`, and its per-colour colour science.

    :meth:`lab_of_codes` and :meth:`codes_of_lab` repeat, operation for operation (the same
    float64 operations in the same order), :func:`fidelity.colour.colorimetry.srgb_to_lab` on
    ``code / 255`` and :func:`to_uint8` of :func:`fidelity.colour.colorimetry.lab_to_srgb`, but on
    channel planes (3, n), ``chunk`` colours at a time, in buffers kept between calls: fresh
    multi-MiB temporaries cost more in page faults and cache misses than the arithmetic does
    (benchmarks/speed/pipeline.py times ``pull_mean``). The piecewise branches (the linear
    segments near black) are evaluated only where they apply. The 3x3 products run as
    (3, 3) @ (3, n) instead of the reference's (n, 3) @ (3, 3); with OpenBLAS both give the
    same bits (tests/coco/test_dataset.py checks the codes, exact, and the Lab values, to 1e-12).
    Not thread-safe: one workspace per thread or process.
    """

    def __init__(self, chunk: int = 8192) -> None:
        self.chunk = int(chunk)
        self._tables: dict[str, np.ndarray] = {}
        self._planes: dict[str, np.ndarray] = {}

    def table(self, dtype: Any = np.int32, fill: int | None = None) -> np.ndarray:
        """A 2^24-entry table (64 MiB) indexed by packed colour, made on first use.

        ``fill``: value of every entry when it is made (the numba kernel keeps its table at
        -1 between images); without it the contents are undefined.
        """
        key = f"{np.dtype(dtype).str}:{fill}"
        t = self._tables.get(key)
        if t is None:
            t = np.empty(1 << 24, dtype=dtype)
            if fill is not None:
                t.fill(fill)
            self._tables[key] = t
        return t

    def plane(self, key: str, n: int, planar: bool = True, dtype: Any = np.float64,
              width: int = 3) -> np.ndarray:
        """Buffer ``key`` as a (width, n) view (``planar``) or an (n, width) one, grown as needed."""
        buf = self._planes.get(key)
        axis = 1 if planar else 0
        if buf is None or buf.shape[axis] < n or buf.dtype != np.dtype(dtype):
            size = max(n, 1024)
            buf = np.zeros((width, size) if planar else (size, width), dtype=dtype)
            self._planes[key] = buf
        return buf[:, :n] if planar else buf[:n]

    # -- the two kernels ------------------------------------------------------------------

    def pull(self, pixels: np.ndarray, alpha: float, kernels: _NumbaKernels | None = None
             ) -> np.ndarray:
        """pull_mean of (N, 3) uint8 pixels; (N, 3) uint8. ``kernels``: the numba passes."""
        if kernels is not None:
            return self._pull_numba(pixels, alpha, kernels)
        n_px = pixels.shape[0]
        little = sys.byteorder == "little"
        quad = self.plane("quad", n_px, False, np.uint8, 4)  # bytes B, G, R, 0
        if little:  # column copies: a reversed-stride copy is many times slower
            quad[:, 0], quad[:, 1], quad[:, 2] = pixels[:, 2], pixels[:, 1], pixels[:, 0]
            packed = quad.view(np.uint32).reshape(-1)  # R << 16 | G << 8 | B
        else:  # pragma: no cover - big-endian machines
            packed = ((pixels[:, 0].astype(np.uint32) << 16) | (pixels[:, 1].astype(np.uint32)
                                                                << 8) | pixels[:, 2])
        srt = np.sort(packed)
        first = np.empty(srt.size, dtype=bool)
        first[:1] = True
        np.not_equal(srt[1:], srt[:-1], out=first[1:])
        starts = np.flatnonzero(first)
        uniq = srt[starts]
        counts = np.diff(starts, append=srt.size).astype(np.float64)
        n = uniq.size
        codes = self.plane("codes", n, True, np.uint8)
        np.right_shift(uniq, 16, out=codes[0], casting="unsafe")
        np.right_shift(uniq, 8, out=codes[1], casting="unsafe")
        np.copyto(codes[2], uniq, casting="unsafe")
        lab = self._lab_planar(codes)
        mean = (lab @ counts) / n_px
        out = self._codes_planar(self._pulled(lab, mean, alpha))  # (3, n) uint8
        result = np.empty((n_px, 3), dtype=np.uint8)
        if little:
            oq = self.plane("quad_out", n, False, np.uint8, 4)
            oq[:, 0], oq[:, 1], oq[:, 2] = out[2], out[1], out[0]
            table = self.table(np.uint32)
            table[uniq] = oq.view(np.uint32).reshape(-1)
            rq = self.plane("quad_res", n_px, False, np.uint8, 4)
            np.take(table, packed, out=rq.view(np.uint32).reshape(-1))
            result[:, 0], result[:, 1], result[:, 2] = rq[:, 2], rq[:, 1], rq[:, 0]
        else:  # pragma: no cover
            idx = self.table(np.int32)
            idx[uniq] = np.arange(n, dtype=np.int32)
            result[:] = out.T[np.take(idx, packed)]
        return result

    def _pull_numba(self, pixels: np.ndarray, alpha: float, k: _NumbaKernels) -> np.ndarray:
        """:meth:`pull` with the integer passes and the colour-science glue compiled.

        The same sort, distinct colours in the same order, counts and float64 operations as
        the numpy path: the same bits.
        """
        n_px = pixels.shape[0]
        packed = self.plane("packed", n_px, False, np.uint32, 1).reshape(-1)
        k.pack(pixels, packed)
        srt = np.sort(packed)
        uniq = self.plane("uniq", n_px, False, np.uint32, 1).reshape(-1)
        counts = self.plane("counts", n_px, False, np.float64, 1).reshape(-1)
        codes = self.plane("codes", n_px, True, np.uint8)
        n = int(k.distinct(srt, uniq, counts, codes[0], codes[1], codes[2]))
        lab = self._lab_planar(codes[:, :n], k)
        mean = (lab @ counts[:n]) / n_px
        out = self._codes_planar(self._pulled(lab, mean, alpha), k)
        table = self.table(np.uint32)
        k.fill_table(table, uniq[:n], out[0], out[1], out[2])
        result = np.empty((n_px, 3), dtype=np.uint8)
        k.gather(table, packed, result)
        return result

    @staticmethod
    def _pulled(lab: np.ndarray, mean: np.ndarray, alpha: float) -> np.ndarray:
        lab -= mean[:, None]
        lab *= np.float64(alpha)
        lab += mean[:, None]  # = mean + α (lab - mean)
        return lab

    # -- per-colour colour science -----------------------------------------------------------

    def lab_of_codes(self, codes: np.ndarray, kernel: str = "numpy") -> np.ndarray:
        """CIELAB (3, N) of sRGB code triples (N, 3) uint8; a view into the workspace."""
        planar = self.plane("codes_in", codes.shape[0], True, np.uint8)
        planar[...] = codes.T
        return self._lab_planar(planar, _kernels_for(kernel))

    def codes_of_lab(self, lab: np.ndarray, kernel: str = "numpy") -> np.ndarray:
        """sRGB code triples (N, 3) uint8 of CIELAB (3, N): ``rint(clip(Lab2RGB, 0, 1) 255)``."""
        src = self.plane("lab_in", lab.shape[1])
        src[...] = lab
        return np.ascontiguousarray(self._codes_planar(src, _kernels_for(kernel)).T)

    def _lab_planar(self, codes: np.ndarray, kernels: _NumbaKernels | None = None
                    ) -> np.ndarray:
        n = codes.shape[1]
        lab = self.plane("lab", n)
        step = self._lab_chunk if kernels is None else self._lab_chunk_numba
        for s in range(0, n, self.chunk):
            e = min(s + self.chunk, n)
            step(codes[:, s:e], lab[:, s:e], kernels)
        return lab

    def _codes_planar(self, lab: np.ndarray, kernels: _NumbaKernels | None = None
                      ) -> np.ndarray:
        n = lab.shape[1]
        out = self.plane("codes_out", n, True, np.uint8)
        step = self._codes_chunk if kernels is None else self._codes_chunk_numba
        for s in range(0, n, self.chunk):
            e = min(s + self.chunk, n)
            step(lab[:, s:e], out[:, s:e], kernels)
        return out

    def _lab_chunk_numba(self, codes: np.ndarray, lab: np.ndarray,
                         k: _NumbaKernels | None) -> None:
        assert k is not None
        n = codes.shape[1]
        lin, t, f = self.plane("lin", n), self.plane("t", n), self.plane("f", n)
        k.lin_of_codes(codes[0], codes[1], codes[2], _srgb_linear_table(), lin[0], lin[1],
                       lin[2])
        np.matmul(MATRIX_LINEAR_SRGB_TO_XYZ, lin, out=t)  # XYZ (3, N)
        k.divide_rows(t[0], t[1], t[2], *WHITEPOINT_D65_XYZ)
        np.cbrt(t, out=f)
        k.lab_of_f(t[0], t[1], t[2], f[0], f[1], f[2], lab[0], lab[1], lab[2], CIE_EPSILON,
                   CIE_KAPPA)

    def _codes_chunk_numba(self, lab: np.ndarray, out: np.ndarray,
                           k: _NumbaKernels | None) -> None:
        assert k is not None
        n = lab.shape[1]
        t, x, p = self.plane("t", n), self.plane("lin", n), self.plane("f", n)
        k.xyz_of_lab(lab[0], lab[1], lab[2], t[0], t[1], t[2], *WHITEPOINT_D65_XYZ,
                     CIE_EPSILON, CIE_KAPPA, CIE_KAPPA * CIE_EPSILON)
        np.matmul(MATRIX_XYZ_TO_LINEAR_SRGB, t, out=x)  # linear sRGB (3, N)
        with np.errstate(invalid="ignore"):
            np.power(x, 1.0 / 2.4, out=p)
        for c in range(3):
            k.encode(p[c], x[c], out[c])

    def _lab_chunk(self, codes: np.ndarray, lab: np.ndarray, _: Any = None) -> None:
        n = codes.shape[1]
        lin = self.plane("lin", n)
        np.take(_srgb_linear_table(), codes, out=lin)
        t = self.plane("t", n)
        np.matmul(MATRIX_LINEAR_SRGB_TO_XYZ, lin, out=t)  # XYZ (3, N)
        t /= np.asarray(WHITEPOINT_D65_XYZ)[:, None]
        f = self.plane("f", n)
        np.cbrt(t, out=f)
        low = self.plane("mask", n, dtype=bool)
        np.less_equal(t, CIE_EPSILON, out=low)
        if low.any():  # (κ t + 16) / 116 at and below ε (few colours: computed there only)
            for i in range(3):
                sel = low[i]
                if sel.any():
                    f[i][sel] = (CIE_KAPPA * t[i][sel] + 16.0) / 116.0
        np.multiply(f[1], 116.0, out=lab[0])
        lab[0] -= 16.0
        np.subtract(f[0], f[1], out=lab[1])
        lab[1] *= 500.0
        np.subtract(f[1], f[2], out=lab[2])
        lab[2] *= 200.0

    def _codes_chunk(self, lab: np.ndarray, out: np.ndarray, _: Any = None) -> None:
        n = lab.shape[1]
        L = lab[0]
        f = self.plane("f", n)
        fy = f[1]
        np.add(L, 16.0, out=fy)
        fy /= 116.0
        np.divide(lab[1], 500.0, out=f[0])
        f[0] += fy  # fy + a / 500
        np.divide(lab[2], 200.0, out=f[2])
        np.subtract(fy, f[2], out=f[2])  # fy - b / 200
        t = self.plane("t", n)
        np.multiply(f, f, out=t)
        t *= f  # f * f * f
        low = self.plane("mask", n, dtype=bool)
        np.less_equal(t, CIE_EPSILON, out=low)
        np.less_equal(L, CIE_KAPPA * CIE_EPSILON, out=low[1])
        if low.any():  # (116 f - 16) / κ at and below ε; Y: L / κ at and below κ ε
            for i in range(3):
                sel = low[i]
                if sel.any():
                    t[i][sel] = (L[sel] / CIE_KAPPA if i == 1
                                 else (116.0 * f[i][sel] - 16.0) / CIE_KAPPA)
        t *= np.asarray(WHITEPOINT_D65_XYZ)[:, None]
        x = self.plane("lin", n)
        np.matmul(MATRIX_XYZ_TO_LINEAR_SRGB, t, out=x)  # linear sRGB (3, N)
        p = f  # reused: sRGB encoding, as fidelity.colour.colorimetry (the power branch above
        with np.errstate(invalid="ignore"):  # 0.0031308, where max(x, 0.0031308) = x;
            np.power(x, 1.0 / 2.4, out=p)  # NaN below 0 is overwritten just after)
        p *= 1.055
        p -= 0.055
        np.less_equal(x, 0.0031308, out=low)
        if low.any():
            for i in range(3):
                sel = low[i]
                if sel.any():
                    p[i][sel] = x[i][sel] * 12.92
        np.clip(p, 0.0, 1.0, out=p)  # to_uint8
        p *= 255.0
        np.rint(p, out=p)
        np.copyto(out, p, casting="unsafe")


@record
class _NumbaKernels:
    """The compiled element-wise passes of the numba pull_mean kernel (:func:`_numba_kernels`)."""

    pack: Callable[..., None]
    distinct: Callable[..., int]
    fill_table: Callable[..., None]
    gather: Callable[..., None]
    lin_of_codes: Callable[..., None]
    divide_rows: Callable[..., None]
    lab_of_f: Callable[..., None]
    xyz_of_lab: Callable[..., None]
    encode: Callable[..., None]


@functools.cache
def _numba_kernels() -> _NumbaKernels | None:
    """The numba pull_mean passes, compiled on first use (cached on disk), or None without numba.

    ``pack``, ``distinct``, ``fill_table`` and ``gather`` are the integer passes of
    :meth:`PullMeanWorkspace.pull` around numpy's sort (pack the pixels into 24-bit keys; the
    distinct keys of the sorted array with their counts and codes; the output codes into the
    2^24-entry table; the table read back onto the pixels), one loop each instead of several
    numpy passes. The others are the element-wise glue of :meth:`PullMeanWorkspace._lab_chunk`
    and ``_codes_chunk`` fused into one loop per step, over contiguous channel rows: the same IEEE
    operations in the same order (numba compiles without fast-math: no reassociation, no FMA
    contraction, ``x / 116.0`` stays a division), while the 3x3 products, ``cbrt`` and
    ``power`` stay the numpy calls of the reference. tests/coco/test_dataset.py checks that both
    kernels give the same bits.
    """
    try:
        numba = importlib.import_module("numba")
    except ImportError:
        return None

    jit = numba.njit(cache=True, nogil=True, boundscheck=False)

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def pack(pixels: np.ndarray, packed: np.ndarray) -> None:
        for p in range(pixels.shape[0]):
            packed[p] = (np.uint32(pixels[p, 0]) << 16) | (np.uint32(pixels[p, 1]) << 8) \
                | np.uint32(pixels[p, 2])

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def distinct(srt: np.ndarray, uniq: np.ndarray, counts: np.ndarray, c0: np.ndarray,
                 c1: np.ndarray, c2: np.ndarray) -> int:
        n = 0
        start = 0
        for q in range(srt.shape[0] + 1):
            if q == srt.shape[0] or (q > 0 and srt[q] != srt[q - 1]):
                key = srt[start]
                uniq[n] = key
                counts[n] = np.float64(q - start)
                c0[n] = np.uint8((key >> 16) & 255)
                c1[n] = np.uint8((key >> 8) & 255)
                c2[n] = np.uint8(key & 255)
                n += 1
                start = q
        return n

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def fill_table(table: np.ndarray, uniq: np.ndarray, o0: np.ndarray, o1: np.ndarray,
                   o2: np.ndarray) -> None:
        for j in range(uniq.shape[0]):
            table[uniq[j]] = (np.uint32(o0[j]) << 16) | (np.uint32(o1[j]) << 8) \
                | np.uint32(o2[j])

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def gather(table: np.ndarray, packed: np.ndarray, out: np.ndarray) -> None:
        for p in range(packed.shape[0]):
            v = table[packed[p]]
            out[p, 0] = np.uint8(v >> 16)
            out[p, 1] = np.uint8((v >> 8) & 255)
            out[p, 2] = np.uint8(v & 255)

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def lin_of_codes(c0: np.ndarray, c1: np.ndarray, c2: np.ndarray, table: np.ndarray,
                     l0: np.ndarray, l1: np.ndarray, l2: np.ndarray) -> None:
        for k in range(c0.shape[0]):
            l0[k] = table[c0[k]]
            l1[k] = table[c1[k]]
            l2[k] = table[c2[k]]

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def divide_rows(t0: np.ndarray, t1: np.ndarray, t2: np.ndarray, w0: float, w1: float,
                    w2: float) -> None:
        for k in range(t0.shape[0]):
            t0[k] = t0[k] / w0
            t1[k] = t1[k] / w1
            t2[k] = t2[k] / w2

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def lab_of_f(t0: np.ndarray, t1: np.ndarray, t2: np.ndarray, f0: np.ndarray,
                 f1: np.ndarray, f2: np.ndarray, L: np.ndarray, A: np.ndarray, B: np.ndarray,
                 eps: float, kappa: float) -> None:
        for k in range(t0.shape[0]):
            fx, fy, fz = f0[k], f1[k], f2[k]
            if t0[k] <= eps:
                fx = (kappa * t0[k] + 16.0) / 116.0
            if t1[k] <= eps:
                fy = (kappa * t1[k] + 16.0) / 116.0
            if t2[k] <= eps:
                fz = (kappa * t2[k] + 16.0) / 116.0
            L[k] = fy * 116.0 - 16.0
            A[k] = (fx - fy) * 500.0
            B[k] = (fy - fz) * 200.0

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def xyz_of_lab(L: np.ndarray, A: np.ndarray, B: np.ndarray, t0: np.ndarray,
                   t1: np.ndarray, t2: np.ndarray, w0: float, w1: float, w2: float,
                   eps: float, kappa: float, kappa_eps: float) -> None:
        for k in range(L.shape[0]):
            lk = L[k]
            fy = (lk + 16.0) / 116.0
            fx = A[k] / 500.0 + fy
            fz = fy - B[k] / 200.0
            tx = fx * fx * fx
            ty = fy * fy * fy
            tz = fz * fz * fz
            if tx <= eps:
                tx = (116.0 * fx - 16.0) / kappa
            if lk <= kappa_eps:
                ty = lk / kappa
            if tz <= eps:
                tz = (116.0 * fz - 16.0) / kappa
            t0[k] = tx * w0
            t1[k] = ty * w1
            t2[k] = tz * w2

    @jit  # type: ignore[untyped-decorator,misc,unused-ignore]
    def encode(p: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
        for k in range(p.shape[0]):
            v = p[k] * 1.055
            v = v - 0.055
            if x[k] <= 0.0031308:
                v = x[k] * 12.92
            v = min(max(v, 0.0), 1.0) * 255.0
            out[k] = np.uint8(np.rint(v))

    return _NumbaKernels(pack, distinct, fill_table, gather, lin_of_codes, divide_rows,
                         lab_of_f, xyz_of_lab, encode)


_WHITE = np.asarray(WHITEPOINT_D65_XYZ, dtype=np.float64)


@functools.cache
def _srgb_linear_table() -> np.ndarray:
    """Linear values of the 256 sRGB code values (:func:`fidelity.colour.colorimetry.linearize_srgb`)."""
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
    files = sorted(p for p in d.iterdir()
                   if p.suffix.lower() in (".jpg", ".jpeg") and not p.name.startswith("."))
    if not files:
        raise InputFileError(f"{d}: no .jpg/.jpeg images in the folder")
    return files


#: Per-process cache of the last built table, so that a pool worker builds a 256^3 table once
#: per subset and not once per image (each worker process has its own copy).
_WORKER_MAP: dict[tuple[str, float | None, str], PixelMap] = {}


def _write_one(args: tuple[str, str, str, float | None, str]) -> str:
    src, dst, name, param, kernel = args
    key = (name, param, kernel)
    pm = _WORKER_MAP.get(key)
    if pm is None:
        _WORKER_MAP.clear()
        pm = _WORKER_MAP[key] = PixelMap.build(name, param)
        pm.kernel = kernel
    rgb, settings = read_jpeg(src)
    write_bytes_atomic(dst, encode_jpeg(pm(rgb), settings))
    return dst


def write_transformed_dataset(images: Sequence[Path], out_dir: str | os.PathLike[str],
                              transform: str, target: float, *, param: float | None = None,
                              workers: int = 1, progress: bool = True,
                              executor: Executor | None = None) -> dict[str, Any]:
    """Write one subset: every image transformed for (``transform``, ΔE ``target``).

    ``param`` overrides the calibrated parameter. Existing outputs are skipped (resumable);
    each file is written atomically; inputs are never overwritten. ``executor``: a pool of
    workers to run on (:func:`start_workers`; :func:`write_grid` starts one for all its
    subsets), else one is started for this subset when ``workers`` > 1. Returns a summary
    dict.
    """
    out = Path(out_dir)
    name = transform
    if target == 0:
        name, param = BASELINE, None
    elif param is None:
        param, reason = calibrated_param(transform, target)
        if param is None:
            raise UnreachableTargetError(reason or f"{transform} at ΔE {target:g} unreachable")
    sub = out / subset_name(transform, target)

    remove_stale_temporaries(sub)  # a killed run's temporary files do not survive the resume
    srcs = {p.resolve() for p in images}
    todo = []
    for p in images:
        dst = sub / p.name
        if dst.resolve() in srcs:
            raise InputFileError(f"{dst}: output would overwrite an input image")
        if not dst.exists():
            todo.append((str(p), str(dst)))
    kernel = run_kernel(len(todo)) if name in PER_IMAGE else "auto"
    jobs = [(src, dst, name, param, kernel) for src, dst in todo]
    sub.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    _run_jobs(jobs, workers, progress, f"{subset_name(transform, target)}", executor)
    return {"subset": sub.name, "transform": name, "target": target, "param": param,
            "written": len(jobs), "skipped": len(images) - len(jobs),
            "seconds": time.perf_counter() - t0}


#: Most images a worker is handed at a time (fewer when the folder is small, so that every
#: worker gets some).
MAX_CHUNK = 8


def pool_size(workers: int, images: int) -> int:
    """Worker processes worth starting for ``images`` images: no more than there are
    images."""
    return max(1, min(int(workers), int(images)))


def _prepare_worker(kernel: str | None) -> None:
    """Make a worker ready before its first image: the pull_mean ``kernel`` loaded (numba's
    from its disk cache), so that the first images do not wait on it. A no-op in a worker
    forked from a process that has it."""
    if kernel is not None:
        pull_mean_uint8(np.zeros((1, 3), np.uint8), 0.5, kernel=kernel)


def start_workers(workers: int, images: int, transforms: Iterable[str]) -> Executor | None:
    """A pool of :func:`pool_size` worker processes for writing ``images`` images with
    ``transforms`` (None when one process is enough: the images are written in this one).

    Each worker is prepared once (:func:`_prepare_worker`, the pull_mean kernel of
    :func:`run_kernel`): where workers are forked, in this process before they start, so that
    they inherit it rather than each doing it again.
    """
    size = pool_size(workers, images)
    if size <= 1:
        return None
    kernel = run_kernel(images) if PER_IMAGE & set(transforms) else None
    if multiprocessing.get_start_method(allow_none=False) == "fork":
        _prepare_worker(kernel)
    return ProcessPoolExecutor(max_workers=size, initializer=_prepare_worker,
                               initargs=(kernel,))


def _run_jobs(jobs: list[tuple[str, str, str, float | None, str]], workers: int, progress: bool,
              desc: str, executor: Executor | None = None) -> None:
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), desc=desc, unit="img", disable=not progress or not jobs)
    try:
        if not jobs:
            return
        pool = executor
        if pool is None:
            pool = start_workers(workers, len(jobs), {j[2] for j in jobs})
        if pool is None:
            for j in jobs:
                _write_one(j)
                bar.update()
            return
        size = pool_size(workers, len(jobs))
        chunk = max(1, min(MAX_CHUNK, len(jobs) // (4 * size)))
        try:
            for _ in pool.map(_write_one, jobs, chunksize=chunk):
                bar.update()
        finally:
            if executor is None:
                pool.shutdown()
    finally:
        bar.close()


def write_grid(images: Sequence[Path], out_dir: str | os.PathLike[str],
               transforms: Iterable[str], targets: Iterable[float], *, workers: int = 1,
               progress: bool = True,
               on_skip: Callable[[str, float, str], None] | None = None) -> list[dict[str, Any]]:
    """Write every (transform, target) subset; unreachable cells are reported, not written."""
    results = []
    done_baseline = False
    names, values = list(transforms), list(targets)
    pool = start_workers(workers, len(images), names)  # started once for every subset
    try:
        for t in names:
            for e in values:
                if e == 0:
                    if done_baseline:
                        continue
                    done_baseline = True
                try:
                    results.append(write_transformed_dataset(
                        images, out_dir, t, e, workers=workers, progress=progress,
                        executor=pool))
                except UnreachableTargetError as exc:
                    results.append({"subset": subset_name(t, e), "transform": t, "target": e,
                                    "skipped_reason": str(exc)})
                    if on_skip:
                        on_skip(t, e, str(exc))
    finally:
        if pool is not None:
            pool.shutdown()
    return results
