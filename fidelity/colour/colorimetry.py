"""Colorimetry: sRGB transfer functions, sRGB <-> CIE XYZ <-> CIELAB, and colour differences.

Conventions (the SAFE-COLOR conventions, ``shared/reference/safecolor.md``):

- sRGB is IEC 61966-2-1:1999: piecewise transfer function with thresholds 0.04045 (encoded) and
  0.0031308 (linear), exponent 2.4; primaries R (0.64, 0.33), G (0.30, 0.60), B (0.15, 0.06).
- The RGB <-> XYZ matrix is derived from the primaries and the D65 chromaticity
  (0.3127, 0.3290), so that sRGB white (1, 1, 1) maps to exactly L* = 100, a* = b* = 0.
- CIELAB is CIE 1976 L*a*b* (CIE 15:2004) relative to D65 with the CIE 1931 2° observer, XYZ
  scaled so that the white has Y = 1. The exact CIE constants ε = 216/24389 and κ = 24389/27.
- ΔE00 is CIEDE2000 with kL = kC = kH = 1 (CIE 142-2001; Sharma, Wu & Dalal 2005).

Every function is vectorised over any leading shape ``(..., 3)``; float32 input gives float32
output and float64 gives float64 (other inputs are computed in float64). Inputs are never
modified.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour import datasets
from fidelity.colour.datasets import adaptation_matrix
from fidelity.core.errors import InvalidValueError, unknown_name

__all__ = [
    "CIE_EPSILON",
    "CIE_KAPPA",
    "DELTA_E_METHODS",
    "MATRIX_LINEAR_SRGB_TO_XYZ",
    "MATRIX_XYZ_TO_LINEAR_SRGB",
    "WHITEPOINT_D65_XY",
    "WHITEPOINT_D65_XYZ",
    "COMMON_RGB_COLOURSPACES",
    "delinearize_srgb",
    "CHROMATIC_ADAPTATION_METHODS",
    "matrix_chromatic_adaptation",
    "matrix_rgb_to_linear_srgb",
    "delta_e",
    "delta_e_1976",
    "delta_e_1994",
    "delta_e_2000",
    "delta_e_2000_components",
    "lab_to_srgb",
    "lab_to_xyz",
    "linear_srgb_to_xyz",
    "linearize_srgb",
    "normalised_primary_matrix",
    "srgb_to_lab",
    "srgb_to_xyz",
    "xyz_to_lab",
    "xyz_to_linear_srgb",
    "xyz_to_srgb",
]

FloatArray = NDArray[np.floating[Any]]

#: CIE 15:2004 constants of the L* function: ε = (6/29)^3 and κ = (29/3)^3.
CIE_EPSILON: float = 216.0 / 24389.0
CIE_KAPPA: float = 24389.0 / 27.0

#: CIE D65 chromaticity (CIE 1931 2° observer) as used by IEC 61966-2-1.
WHITEPOINT_D65_XY: tuple[float, float] = (0.3127, 0.3290)

_SRGB_PRIMARIES_XY = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06))


def _xy_to_xyz(xy: ArrayLike) -> NDArray[np.float64]:
    """CIE xy chromaticity to XYZ with Y = 1."""
    x, y = np.asarray(xy, dtype=np.float64)
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def normalised_primary_matrix(
    primaries_xy: ArrayLike, whitepoint_xy: ArrayLike
) -> NDArray[np.float64]:
    """The 3x3 matrix from linear RGB to XYZ for RGB primaries and a white point.

    SMPTE RP 177-1993, section 3.3: the columns are the primaries' XYZ (Y = 1) scaled so that
    RGB (1, 1, 1) maps to the white point's XYZ with Y = 1.

    ``primaries_xy``: (3, 2) chromaticities of R, G, B; ``whitepoint_xy``: (2,).
    """
    p = np.asarray(primaries_xy, dtype=np.float64)
    columns = np.stack([_xy_to_xyz(c) for c in p], axis=1)
    scale = np.linalg.solve(columns, _xy_to_xyz(whitepoint_xy))
    return columns * scale


#: Linear sRGB -> XYZ (D65, Y of white = 1), derived from the IEC 61966-2-1 primaries.
MATRIX_LINEAR_SRGB_TO_XYZ: NDArray[np.float64] = normalised_primary_matrix(
    _SRGB_PRIMARIES_XY, WHITEPOINT_D65_XY
)
#: XYZ -> linear sRGB, the exact inverse of :data:`MATRIX_LINEAR_SRGB_TO_XYZ`.
MATRIX_XYZ_TO_LINEAR_SRGB: NDArray[np.float64] = np.asarray(
    np.linalg.inv(MATRIX_LINEAR_SRGB_TO_XYZ), dtype=np.float64)
#: XYZ of the D65 white with Y = 1: (0.95046, 1, 1.08906).
WHITEPOINT_D65_XYZ: NDArray[np.float64] = _xy_to_xyz(WHITEPOINT_D65_XY)

MATRIX_LINEAR_SRGB_TO_XYZ.setflags(write=False)
MATRIX_XYZ_TO_LINEAR_SRGB.setflags(write=False)
WHITEPOINT_D65_XYZ.setflags(write=False)


def _as_float(a: ArrayLike) -> FloatArray:
    """``a`` as a float array: float32 and float64 kept, everything else as float64."""
    arr = np.asarray(a)
    if arr.dtype in (np.float32, np.float64):
        return arr
    return arr.astype(np.float64)


def _check_last_axis(a: FloatArray, name: str) -> None:
    if a.ndim == 0 or a.shape[-1] != 3:
        raise InvalidValueError(f"{name} must have shape (..., 3), got {a.shape}")


# --------------------------------------------------------------------------------------------
# sRGB transfer function (IEC 61966-2-1:1999, section 5.2)
# --------------------------------------------------------------------------------------------


def linearize_srgb(v: ArrayLike) -> FloatArray:
    """sRGB electro-optical transfer: encoded value V' -> linear value V.

    IEC 61966-2-1: V = V'/12.92 for V' <= 0.04045, else ((V' + 0.055)/1.055)^2.4.
    Domain: any real (values below 0.04045, negatives included, follow the linear segment;
    values above 1 follow the power segment). Range: same extension of [0, 1].
    """
    x = _as_float(v)
    dtype = x.dtype.type
    power = np.power((np.maximum(x, dtype(0.04045)) + dtype(0.055)) / dtype(1.055), dtype(2.4))
    return np.where(x <= dtype(0.04045), x / dtype(12.92), power)


def delinearize_srgb(v: ArrayLike) -> FloatArray:
    """sRGB inverse transfer: linear value V -> encoded value V'.

    IEC 61966-2-1: V' = 12.92 V for V <= 0.0031308, else 1.055 V^(1/2.4) - 0.055.
    Domain: any real (negatives follow the linear segment). Range: extension of [0, 1].
    """
    x = _as_float(v)
    dtype = x.dtype.type
    # in place, the linear segment written over the power (np.where's result, one array less)
    out = np.maximum(x, dtype(0.0031308), out=np.empty_like(x))
    np.power(out, dtype(1.0 / 2.4), out=out)
    out *= dtype(1.055)
    out -= dtype(0.055)
    linear = x <= dtype(0.0031308)
    np.copyto(out, x * dtype(12.92), where=linear)
    return out


# --------------------------------------------------------------------------------------------
# sRGB <-> XYZ <-> CIELAB
# --------------------------------------------------------------------------------------------


def _matmul_last(a: FloatArray, m: NDArray[np.float64]) -> FloatArray:
    return a @ m.T.astype(a.dtype, copy=False)


def linear_srgb_to_xyz(rgb: ArrayLike) -> FloatArray:
    """Linear sRGB (..., 3) -> CIE XYZ (..., 3), D65, Y of white = 1 (IEC 61966-2-1)."""
    a = _as_float(rgb)
    _check_last_axis(a, "rgb")
    return _matmul_last(a, MATRIX_LINEAR_SRGB_TO_XYZ)


def xyz_to_linear_srgb(xyz: ArrayLike) -> FloatArray:
    """CIE XYZ (..., 3), D65, Y of white = 1 -> linear sRGB (..., 3), unclipped."""
    a = _as_float(xyz)
    _check_last_axis(a, "xyz")
    return _matmul_last(a, MATRIX_XYZ_TO_LINEAR_SRGB)


def srgb_to_xyz(rgb: ArrayLike) -> FloatArray:
    """Encoded sRGB (..., 3), nominally [0, 1] -> CIE XYZ (..., 3) with Y of white = 1."""
    return linear_srgb_to_xyz(linearize_srgb(rgb))


def xyz_to_srgb(xyz: ArrayLike) -> FloatArray:
    """CIE XYZ (..., 3), Y of white = 1 -> encoded sRGB (..., 3), unclipped."""
    return delinearize_srgb(xyz_to_linear_srgb(xyz))


def xyz_to_lab(xyz: ArrayLike, white: ArrayLike = WHITEPOINT_D65_XYZ) -> FloatArray:
    """CIE XYZ -> CIE 1976 L*a*b* (CIE 15:2004, section 8.2.1).

    ``xyz``: (..., 3) with the white ``white`` (3,) on the same scale (default D65, Y = 1).
    Range: L* in [0, 100] for 0 <= Y <= Y_white; a*, b* unbounded.
    """
    a = _as_float(xyz)
    _check_last_axis(a, "xyz")
    dtype = a.dtype.type
    t = a / np.asarray(white, dtype=a.dtype)
    f = np.where(
        t > dtype(CIE_EPSILON),
        np.cbrt(t),
        (dtype(CIE_KAPPA) * t + dtype(16.0)) / dtype(116.0),
    )
    fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
    lab = np.empty(f.shape, f.dtype)  # np.stack's array (C order), filled in place: faster
    lab[..., 0] = dtype(116.0) * fy - dtype(16.0)
    lab[..., 1] = dtype(500.0) * (fx - fy)
    lab[..., 2] = dtype(200.0) * (fy - fz)
    return lab


def lab_to_xyz(lab: ArrayLike, white: ArrayLike = WHITEPOINT_D65_XYZ) -> FloatArray:
    """CIE 1976 L*a*b* -> CIE XYZ on the scale of ``white`` (CIE 15:2004, inverse of 8.2.1)."""
    a = _as_float(lab)
    _check_last_axis(a, "lab")
    dtype = a.dtype.type
    L = a[..., 0]
    fy = (L + dtype(16.0)) / dtype(116.0)
    f = np.stack([fy + a[..., 1] / dtype(500.0), fy, fy - a[..., 2] / dtype(200.0)], axis=-1)
    f3 = f * f * f
    t = np.where(f3 > dtype(CIE_EPSILON), f3, (dtype(116.0) * f - dtype(16.0)) / dtype(CIE_KAPPA))
    # Y follows from L* directly (CIE 15:2004), which is exact on the linear segment.
    t[..., 1] = np.where(L > dtype(CIE_KAPPA * CIE_EPSILON), f3[..., 1], L / dtype(CIE_KAPPA))
    return t * np.asarray(white, dtype=a.dtype)


def srgb_to_lab(rgb: ArrayLike) -> FloatArray:
    """Encoded sRGB (..., 3) -> CIELAB relative to D65 (the SAFE-COLOR RGB2Lab)."""
    return xyz_to_lab(srgb_to_xyz(rgb))


def lab_to_srgb(lab: ArrayLike) -> FloatArray:
    """CIELAB relative to D65 (..., 3) -> encoded sRGB (..., 3), unclipped (SAFE-COLOR Lab2RGB)."""
    return xyz_to_srgb(lab_to_xyz(lab))


# --------------------------------------------------------------------------------------------
# Colour differences
# --------------------------------------------------------------------------------------------

_TWO_PI = 2.0 * np.pi
_POW25_7 = 25.0**7
_DEG = np.pi / 180.0


def _result_dtype(lab1: ArrayLike, lab2: ArrayLike) -> type[np.floating[Any]]:
    """float32 when both inputs are float32, else float64."""
    both32 = np.asarray(lab1).dtype == np.float32 and np.asarray(lab2).dtype == np.float32
    return np.float32 if both32 else np.float64


def _lab_pair(lab1: ArrayLike, lab2: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Both CIELAB inputs as float64 (differences are computed in float64 for accuracy)."""
    a = np.asarray(lab1)
    b = np.asarray(lab2)
    a = a.astype(np.float64, copy=False)
    b = b.astype(np.float64, copy=False)
    _check_last_axis(a, "lab1")
    _check_last_axis(b, "lab2")
    return a, b


#: Pairs per block: the block's temporaries stay in the CPU cache instead of main memory.
_BLOCK = 8192


def _ciede2000_block(
    L1: FloatArray, a1: FloatArray, b1: FloatArray,
    L2: FloatArray, a2: FloatArray, b2: FloatArray,
    components: bool,
) -> list[FloatArray]:
    """CIEDE2000 on 1-D contiguous component arrays; see :func:`delta_e_2000`.

    Sharma, Wu & Dalal (2005) eq. 2-22, rewritten to do less work with identical results:
    hue angles are handled as unit vectors (a'/C', b/C'), so the mean hue h̄' is the bisector
    of the shorter arc (which is what eq. 14's case split computes) and needs one arctan2
    instead of two; ΔH' = 2 sqrt(C1'C2') sin(Δh'/2) = sqrt(C1'C2') |u1 - u2| (the chord) with
    the sign of the cross product; the cosines of T come from one (cos, sin) pair by the
    multiple-angle formulas; powers are products. No degree/radian round trips.
    """
    dt = L1.dtype.type
    b1s = b1 * b1
    b2s = b2 * b2
    c7 = np.sqrt(a1 * a1 + b1s)
    c7 += np.sqrt(a2 * a2 + b2s)
    c7 *= dt(0.5)  # C̄*ab
    cm = c7.copy()
    c7 *= c7
    c7 *= c7 * c7
    c7 *= cm  # C̄^7
    g1 = c7 / (c7 + dt(_POW25_7))
    np.sqrt(g1, out=g1)
    g1 *= dt(-0.5)
    g1 += dt(1.5)  # 1 + G
    a1p = a1 * g1
    a2p = a2 * g1
    c1p = np.sqrt(a1p * a1p + b1s)
    c2p = np.sqrt(a2p * a2p + b2s)

    # Unit hue vectors; an achromatic colour (C' = 0) takes the other colour's hue, which is
    # eq. 10 and 14's rule for C1'C2' = 0 (Δh' = 0, h̄' = h1' + h2' with h' = 0 when C' = 0).
    z1 = c1p == 0
    z2 = c2p == 0
    with np.errstate(invalid="ignore", divide="ignore"):
        x1 = a1p / c1p
        y1 = b1 / c1p
        x2 = a2p / c2p
        y2 = b2 / c2p
    if z1.any() or z2.any():
        both = z1 & z2
        x1 = np.where(z1, np.where(both, dt(1.0), x2), x1)
        y1 = np.where(z1, np.where(both, dt(0.0), y2), y1)
        x2 = np.where(z2, x1, x2)
        y2 = np.where(z2, y1, y2)

    # Hues exactly 180° apart (eq. 10 and 14 at their boundary; Sharma's pair 14): the cross
    # product a1' b2 - b1 a2' of the raw (a', b) vectors is then exactly zero, and the pair takes
    # the "|h2' - h1'| <= 180°" branch, as the formula prescribes for equality: h̄' is the
    # arithmetic mean of the hues in [0°, 360°) and Δh' = h2' - h1'. Deciding this from the exact
    # geometry, not from rounded arctan2 values, makes the result deterministic.
    cross = a1p * b2 - b1 * a2p
    antipodal = (cross == 0) & (x1 * x2 + y1 * y2 < 0)
    sign = np.sign(cross)
    bx = x1 + x2
    by = y1 + y2
    if antipodal.any():
        h1 = np.mod(np.arctan2(y1, x1), dt(_TWO_PI))
        h2 = np.mod(np.arctan2(y2, x2), dt(_TWO_PI))
        first_lower = h1 <= h2  # h̄' = min + 90°: rotate the lower hue's vector by +90°
        bx = np.where(antipodal, np.where(first_lower, -y1, -y2), bx)
        by = np.where(antipodal, np.where(first_lower, x1, x2), by)
        sign = np.where(antipodal, np.where(first_lower, dt(1.0), dt(-1.0)), sign)

    chord = (x1 - x2) ** 2
    chord += (y1 - y2) ** 2
    np.sqrt(chord, out=chord)
    dH = np.sqrt(c1p * c2p)
    dH *= chord
    dH *= sign
    dL = L2 - L1
    dC = c2p - c1p
    if components:
        return [dL, dC, dH]

    norm = np.sqrt(bx * bx + by * by)
    c = bx / norm
    s = by / norm
    hbar = np.arctan2(s, c)
    hbar += np.where(hbar < 0, dt(_TWO_PI), dt(0.0))
    # T = 1 - .17 cos(h-30°) + .24 cos 2h + .32 cos(3h+6°) - .20 cos(4h-63°)   (eq. 15)
    cc = c * c
    c2 = dt(2.0) * cc - dt(1.0)
    s2 = dt(2.0) * s * c
    c3 = c * (dt(4.0) * cc - dt(3.0))
    s3 = s * (dt(4.0) * cc - dt(1.0))
    c4 = dt(2.0) * c2 * c2 - dt(1.0)
    s4 = dt(2.0) * s2 * c2
    T = dt(1.0) - dt(0.17 * np.cos(30 * _DEG)) * c
    T -= dt(0.17 * np.sin(30 * _DEG)) * s
    T += dt(0.24) * c2
    T += dt(0.32 * np.cos(6 * _DEG)) * c3
    T -= dt(0.32 * np.sin(6 * _DEG)) * s3
    T -= dt(0.20 * np.cos(63 * _DEG)) * c4
    T -= dt(0.20 * np.sin(63 * _DEG)) * s4
    lbar = (L1 + L2) * dt(0.5) - dt(50.0)
    lbar *= lbar
    SL = dt(0.015) * lbar / np.sqrt(dt(20.0) + lbar)
    SL += dt(1.0)
    cbarp = (c1p + c2p) * dt(0.5)
    SC = dt(1.0) + dt(0.045) * cbarp
    SH = cbarp * T
    SH *= dt(0.015)
    SH += dt(1.0)
    cb7 = cbarp * cbarp
    cb7 *= cb7 * cb7
    cb7 *= cbarp
    RC = cb7 / (cb7 + dt(_POW25_7))
    np.sqrt(RC, out=RC)
    # Δθ = 30° exp(-((h̄' - 275°)/25°)^2); R_T = -sin(2 Δθ) R_C    (eq. 17-20)
    z = hbar - dt(275.0 * _DEG)
    z *= dt(1.0 / (25.0 * _DEG))
    z *= z
    np.negative(z, out=z)
    np.exp(z, out=z)
    z *= dt(60.0 * _DEG)
    RT = np.sin(z, out=z)
    RT *= RC
    RT *= dt(2.0)  # R_C = 2 sqrt(C̄'^7 / (C̄'^7 + 25^7))
    dL /= SL
    dC /= SC
    dH /= SH
    out = dL * dL
    out += dC * dC
    out += dH * dH
    dC *= dH
    dC *= RT
    out -= dC  # R_T = -sin(2Δθ) R_C
    return [np.sqrt(out, out=out)]


def _ciede2000(
    lab1: ArrayLike, lab2: ArrayLike, components: bool
) -> list[FloatArray]:
    """Run :func:`_ciede2000_block` over cache-sized blocks of the broadcast inputs."""
    out_dtype = _result_dtype(lab1, lab2)
    p, q = _lab_pair(lab1, lab2)
    p, q = np.broadcast_arrays(p, q)
    shape = p.shape[:-1]
    p2 = p.reshape(-1, 3)
    q2 = q.reshape(-1, 3)
    n = p2.shape[0]
    n_out = 3 if components else 1
    outs = [np.empty(n, dtype=p.dtype) for _ in range(n_out)]
    for i in range(0, n, _BLOCK):
        j = min(i + _BLOCK, n)
        pc = np.ascontiguousarray(p2[i:j].T)
        qc = np.ascontiguousarray(q2[i:j].T)
        res = _ciede2000_block(pc[0], pc[1], pc[2], qc[0], qc[1], qc[2], components)
        for o, r in zip(outs, res, strict=True):
            o[i:j] = r
    return [o.reshape(shape).astype(out_dtype, copy=False) for o in outs]


def delta_e_2000(lab1: ArrayLike, lab2: ArrayLike) -> FloatArray:
    """CIEDE2000 colour difference ΔE00 between two CIELAB colours, kL = kC = kH = 1.

    CIE 142-2001; implementation notes and test data: G. Sharma, W. Wu, E. N. Dalal, Color
    Res. Appl. 30(1), 2005 (all 34 test pairs reproduced to 1e-4).

    Computed in float64; float32 inputs give a float32 result. Hues exactly 180° apart take
    the ``|Δh'| <= 180°`` branch deterministically (see source).

    Parameters
    ----------
    lab1, lab2
        CIELAB colours, shape (..., 3), broadcastable against each other: L* in [0, 100]
        (domain scale 100), a*, b* real.

    Returns
    -------
    numpy.ndarray
        ΔE00 >= 0, shape (...,) (the broadcast shape less the last axis); symmetric in its
        arguments; float32 when both inputs are float32, else float64.

    Raises
    ------
    InvalidValueError
        An input whose last axis is not of length 3 (a :class:`FidelityError`: exit code 2 on
        the command line).

    References
    ----------
    CIE 142-2001, *Improvement to industrial colour-difference evaluation*; G. Sharma, W. Wu,
    E. N. Dalal, *The CIEDE2000 color-difference formula: implementation notes, supplementary
    test data, and mathematical observations*, Color Res. Appl. 30(1), 21-30, 2005.
    """
    return _ciede2000(lab1, lab2, components=False)[0]


def delta_e_2000_components(
    lab1: ArrayLike, lab2: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The unweighted CIEDE2000 differences (ΔL', ΔC', ΔH') of ``lab2`` relative to ``lab1``.

    Sharma et al. 2005, eq. 8-11: ΔL' = L2 - L1, ΔC' = C2' - C1', ΔH' = 2 sqrt(C1' C2')
    sin(Δh'/2). Positive ΔL' means lighter, positive ΔC' more chromatic than ``lab1``.
    """
    dL, dC, dH = _ciede2000(lab1, lab2, components=True)
    return dL, dC, dH


def delta_e_1976(lab1: ArrayLike, lab2: ArrayLike) -> FloatArray:
    """CIE 1976 colour difference ΔE*ab: Euclidean distance in CIELAB (CIE 15:2004)."""
    out_dtype = _result_dtype(lab1, lab2)
    p, q = _lab_pair(lab1, lab2)
    d = q - p
    out: FloatArray = np.sqrt(np.sum(d * d, axis=-1)).astype(out_dtype, copy=False)
    return out


def delta_e_1994(lab1: ArrayLike, lab2: ArrayLike, textiles: bool = False) -> FloatArray:
    """CIE 1994 colour difference ΔE94 of ``lab2`` from the reference ``lab1`` (CIE 116-1995).

    ΔE94 = sqrt((ΔL*/(kL SL))² + (ΔC*ab/(kC SC))² + (ΔH*ab/(kH SH))²) with SL = 1,
    SC = 1 + K1 C*1, SH = 1 + K2 C*1, kC = kH = 1, where C*1 is the chroma of ``lab1`` (the
    reference: the formula is not symmetric) and ΔH*ab² = Δa*² + Δb*² - ΔC*ab² (clipped at 0).
    Graphic arts: kL = 1, K1 = 0.045, K2 = 0.015; ``textiles``: kL = 2, K1 = 0.048,
    K2 = 0.014. The same convention as colour-science's ``delta_E_CIE1994``.

    ``lab1``, ``lab2``: (..., 3) broadcastable CIELAB. Returns (...,) ΔE94 >= 0; float32
    inputs give a float32 result.
    """
    out_dtype = _result_dtype(lab1, lab2)
    p, q = _lab_pair(lab1, lab2)
    k_l, k1, k2 = (2.0, 0.048, 0.014) if textiles else (1.0, 0.045, 0.015)
    c1 = np.hypot(p[..., 1], p[..., 2])
    c2 = np.hypot(q[..., 1], q[..., 2])
    d_l = p[..., 0] - q[..., 0]
    d_c = c1 - c2
    d_h2 = np.maximum((p[..., 1] - q[..., 1]) ** 2 + (p[..., 2] - q[..., 2]) ** 2 - d_c ** 2,
                      0.0)
    s_c, s_h = 1.0 + k1 * c1, 1.0 + k2 * c1
    out: FloatArray = np.sqrt((d_l / k_l) ** 2 + (d_c / s_c) ** 2 + d_h2 / s_h ** 2).astype(
        out_dtype, copy=False)
    return out


#: Colour-difference methods by name, for ``delta_e(..., method=...)``.
DELTA_E_METHODS: dict[str, Callable[[ArrayLike, ArrayLike], FloatArray]] = {
    "CIE 2000": delta_e_2000,
    "CIE 1994": delta_e_1994,
    "CIE 1976": delta_e_1976,
}


def delta_e(lab1: ArrayLike, lab2: ArrayLike, method: str = "CIE 2000") -> FloatArray:
    """Colour difference between CIELAB colours by a method of :data:`DELTA_E_METHODS`."""
    try:
        fn = DELTA_E_METHODS[method]
    except KeyError:
        raise unknown_name("colour-difference method", method, DELTA_E_METHODS) from None
    return fn(lab1, lab2)


#: Chromatic adaptation transforms (von Kries-type, cone-space matrices from colour-science
#: ``CHROMATIC_ADAPTATION_TRANSFORMS``): Bradford (Lam 1985, ICC v4), CAT02 (CIECAM02),
#: CAT16 (CAM16), Von Kries (Hunt-Pointer-Estevez), XYZ Scaling.
CHROMATIC_ADAPTATION_METHODS: tuple[str, ...] = (
    "Bradford",
    "CAT02",
    "CAT16",
    "Von Kries",
    "XYZ Scaling",
)


def matrix_chromatic_adaptation(
    white_source: ArrayLike, white_target: ArrayLike, method: str = "Bradford"
) -> FloatArray:
    """3x3 von Kries-type adaptation matrix M with XYZ_target = M @ XYZ_source.

    M = A^-1 diag(A w_t / A w_s) A, A the cone-response matrix of ``method``
    (Fairchild, Color Appearance Models, 3rd ed., ch. 9). Whites are XYZ (Y > 0).
    """
    key = next((k for k in CHROMATIC_ADAPTATION_METHODS if k.lower() == method.lower()), None)
    a = adaptation_matrix(key) if key is not None else None
    if a is None:
        raise unknown_name("chromatic adaptation transform", method, CHROMATIC_ADAPTATION_METHODS)
    ws = a @ np.asarray(white_source, dtype=np.float64)
    wt = a @ np.asarray(white_target, dtype=np.float64)
    return np.linalg.inv(a) @ np.diag(wt / ws) @ a


#: Names of colour-science RGB colourspaces that renderers commonly write (any key of
#: ``colour.RGB_COLOURSPACES`` is accepted).
COMMON_RGB_COLOURSPACES: tuple[str, ...] = (
    "sRGB", "ACEScg", "ACES2065-1", "ITU-R BT.2020", "Display P3", "Adobe RGB (1998)",
)


def matrix_rgb_to_linear_srgb(
    colourspace: str | ArrayLike = "sRGB", chromatic_adaptation: str = "Bradford"
) -> NDArray[np.float64]:
    """The 3 x 3 matrix ``M`` with ``linear sRGB = M @ linear RGB`` of ``colourspace``.

    Parameters
    ----------
    colourspace
        A name of ``colour.RGB_COLOURSPACES`` (``"ACEScg"``, ``"ITU-R BT.2020"``,
        ``"Display P3"``, ...; case-insensitive), or the 8 numbers of OpenEXR's
        ``chromaticities`` attribute: ``Rx, Ry, Gx, Gy, Bx, By, Wx, Wy`` (CIE 1931 xy).
    chromatic_adaptation
        Transform that adapts the colourspace's white to D65 when they differ (ACES: about
        D60), one of :data:`CHROMATIC_ADAPTATION_METHODS`.

    Notes
    -----
    The colourspace's RGB -> XYZ matrix (its specification's own, or, for chromaticities, the
    normalised primary matrix: SMPTE RP 177-1993, :func:`normalised_primary_matrix`) and the
    normalised primary matrix of sRGB, the whites adapted by
    ``chromatic_adaptation`` (:func:`matrix_chromatic_adaptation`), as
    ``colour.matrix_RGB_to_RGB`` computes it (tested equal); the result is exact identity for
    sRGB. The primaries of :data:`fidelity.colour.datasets.COLOURSPACES` ship with fidelity,
    other colour-science names are looked up there. Linear values only: a transfer function
    is not part of the matrix.
    """
    if isinstance(colourspace, str):
        if colourspace.strip().lower() == "srgb":
            return np.eye(3)
        shipped = {k.lower(): k for k in datasets.COLOURSPACES}.get(colourspace.strip().lower())
        if shipped is not None:
            found = datasets.colourspace(shipped)
            assert found is not None
            _, white, to_xyz = found
        else:
            import colour

            spaces = {k.lower(): k for k in colour.RGB_COLOURSPACES}
            key = spaces.get(colourspace.strip().lower())
            if key is None:
                raise unknown_name("RGB colourspace", colourspace, COMMON_RGB_COLOURSPACES)
            white = np.asarray(colour.RGB_COLOURSPACES[key].whitepoint, np.float64)
            to_xyz = np.asarray(colour.RGB_COLOURSPACES[key].matrix_RGB_to_XYZ, np.float64)
    else:
        xy = np.asarray(colourspace, dtype=np.float64).ravel()
        if xy.shape != (8,) or not np.all(np.isfinite(xy)) or np.any(xy[1::2] <= 0):
            raise InvalidValueError(f"chromaticities {np.asarray(colourspace).tolist()!r}: "
                                    f"expected 8 finite numbers Rx, Ry, Gx, Gy, Bx, By, Wx, Wy "
                                    f"with y > 0")
        if np.allclose(xy, [0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290], atol=5e-5):
            return np.eye(3)
        white = xy[6:]
        primaries = xy[:6].reshape(3, 2)
        corners = np.hstack([primaries, np.ones((3, 1))])
        if abs(np.linalg.det(corners)) < 1e-9:  # twice the area of the primaries' triangle
            shown = [float(f"{v:.6g}") for v in xy]
            raise InvalidValueError(f"chromaticities {shown}: the three primaries lie "
                                    f"on one line (or point) of the xy diagram: no RGB "
                                    f"colourspace has them; give --colourspace")
        to_xyz = normalised_primary_matrix(primaries, white)
    if chromatic_adaptation not in CHROMATIC_ADAPTATION_METHODS:
        raise unknown_name("chromatic adaptation transform", chromatic_adaptation,
                           CHROMATIC_ADAPTATION_METHODS)
    srgb = datasets.colourspace("sRGB")
    assert srgb is not None
    cat = matrix_chromatic_adaptation(_xy_to_xyz(white), _xy_to_xyz(srgb[1]),
                                      chromatic_adaptation)
    return np.asarray(np.linalg.inv(normalised_primary_matrix(srgb[0], srgb[1]))
                      @ (cat @ to_xyz), dtype=np.float64)

