"""Chart measurement: per-patch CIEDE2000 of measured sRGB against reference CIELAB.

The SAFE-COLOR chart ΔE of an image is the mean ΔE00 over the chart's patches, each patch's
encoded sRGB converted to CIELAB (D65) and compared with the reference Lab
(``shared/reference/safecolor.md``, "Colour difference").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour.colorimetry import delta_e_2000, delta_e_2000_components, srgb_to_lab
from fidelity.errors import InvalidValueError

__all__ = ["ChartMeasurement", "chart_delta_e", "measure_chart"]

F64 = NDArray[np.float64]


def _patch_array(values: ArrayLike, name: str, n: int | None = None) -> F64:
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(n, 3)"
        raise InvalidValueError(f"{name} must have shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = sorted({int(i) + 1 for i in np.argwhere(~np.isfinite(a))[:, 0]})
        raise InvalidValueError(f"{name} has NaN or Inf values (patches {bad})")
    return a


def chart_delta_e(srgb: ArrayLike, reference_lab: ArrayLike) -> float:
    """Mean ΔE00 of encoded sRGB patches (n, 3) against reference CIELAB D65 (n, 3).

    The SAFE-COLOR chart ΔE. Domain: finite sRGB (values outside [0, 1] are taken as they are).
    """
    return float(np.mean(delta_e_2000(srgb_to_lab(srgb), reference_lab)))


@dataclass(frozen=True)
class ChartMeasurement:
    """Measured chart colours and their CIEDE2000 differences from the reference.

    ``delta_l``, ``delta_c``, ``delta_h`` are the unweighted CIEDE2000 differences ΔL', ΔC', ΔH'
    of the measured colour relative to the reference (positive ΔL': lighter than reference).
    ``noise`` is the per-patch standard deviation of the sampled pixels (encoded sRGB), if known.
    """

    patch_names: tuple[str, ...]
    srgb: F64
    lab: F64
    reference_lab: F64
    delta_e: F64
    delta_l: F64
    delta_c: F64
    delta_h: F64
    reference_srgb: F64 | None = None
    noise: F64 | None = None

    @property
    def mean_delta_e(self) -> float:
        """Mean ΔE00 over the patches: the chart ΔE."""
        return float(np.mean(self.delta_e))

    @property
    def max_delta_e(self) -> float:
        """Largest per-patch ΔE00."""
        return float(np.max(self.delta_e))

    @property
    def worst_patch(self) -> str:
        """Name of the patch with the largest ΔE00."""
        return self.patch_names[int(np.argmax(self.delta_e))]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: mean/max ΔE00 and one entry per patch in chart order."""

        def vec(a: F64 | None, i: int) -> list[float] | None:
            return None if a is None else [float(v) for v in a[i]]

        return {
            "mean_delta_e": self.mean_delta_e,
            "max_delta_e": self.max_delta_e,
            "worst_patch": self.worst_patch,
            "patches": [
                {
                    "name": name,
                    "delta_e": float(self.delta_e[i]),
                    "delta_l": float(self.delta_l[i]),
                    "delta_c": float(self.delta_c[i]),
                    "delta_h": float(self.delta_h[i]),
                    "lab": vec(self.lab, i),
                    "reference_lab": vec(self.reference_lab, i),
                    "srgb": vec(self.srgb, i),
                    "reference_srgb": vec(self.reference_srgb, i),
                    "noise": vec(self.noise, i),
                }
                for i, name in enumerate(self.patch_names)
            ],
        }


def measure_chart(
    srgb: ArrayLike,
    reference_lab: ArrayLike,
    patch_names: Sequence[str],
    *,
    reference_srgb: ArrayLike | None = None,
    noise: ArrayLike | None = None,
) -> ChartMeasurement:
    """Measure chart patches: encoded sRGB (n, 3) against reference CIELAB D65 (n, 3).

    Raises :class:`~fidelity.errors.InvalidValueError` for wrong shapes or NaN/Inf values,
    naming the patches concerned.
    """
    names = tuple(str(n) for n in patch_names)
    n = len(names)
    rgb = _patch_array(srgb, "measured sRGB", n)
    ref = _patch_array(reference_lab, "reference Lab", n)
    lab = srgb_to_lab(rgb)
    dl, dc, dh = delta_e_2000_components(ref, lab)
    return ChartMeasurement(
        patch_names=names,
        srgb=rgb,
        lab=lab,
        reference_lab=ref,
        delta_e=delta_e_2000(lab, ref),
        delta_l=dl,
        delta_c=dc,
        delta_h=dh,
        reference_srgb=None if reference_srgb is None else _patch_array(reference_srgb, "reference sRGB", n),
        noise=None if noise is None else np.asarray(noise, dtype=np.float64),
    )
