"""Sharpness of a camera model: the ISO 12233:2017 edge-based spatial frequency response (e-SFR).

:func:`esfr` measures the e-SFR (the MTF along the edge normal) of one slanted-edge region of
interest, one channel of linear values, the way ISO 12233:2017 Annex D and Burns' sfrmat3/sfrmat4
do:

1. Orientation: an edge whose transition runs along the rows (a horizontal edge) is transposed,
   so that the work is always on a vertical-ish edge (transition along the columns). The
   polarity (dark to light or light to dark, left to right) is read from the ROI's two ends and
   only flips the sign of the derivatives; the MTF does not depend on it.
2. Edge location per row: the centroid of the row's first difference ``[-1, 1]`` (placed half a
   pixel between the two pixels it takes), weighted by a Hamming window. As sfrmat does, twice:
   first with the window centred on the ROI, then centred on each row's edge from the first fit.
3. A polynomial fit of edge position against row (first order, as ISO 12233:2017; ``degree=2``
   for a curved edge, as sfrmat4). The edge angle is that of the first-order fit.
4. The rows are cut to a whole number of phase cycles (``floor(rows * |slope|) / |slope|`` rows,
   ISO 12233:2017 / sfrmat3), so that every quarter-pixel phase is sampled alike.
5. The 4x oversampled edge spread function (ESF): each pixel's distance to the fitted edge,
   measured along the edge normal (``cos`` of the edge angle, as sfrmat4 and ISO 12233:2017:
   frequencies are per pixel normal to the edge), is binned at a quarter pixel; the ESF is the
   mean of each bin, at the bin's centre; an empty bin is interpolated from its neighbours.
6. The line spread function (LSF): the ESF's central difference ``[-1/2, 0, 1/2]``.
7. A Hamming window over the whole LSF, centred on its peak (the fitted edge, distance 0).
8. The modulus of the DFT (zero-padded to a power of two at least twice the LSF's length, which
   only samples the same transform more finely), normalised to 1 at f = 0, divided by the
   central difference's own response ``sinc(2 f d)`` (``d`` the bin width: the ISO 12233:2017
   derivative correction). Frequencies in cycles per pixel, reported from 0 to
   :data:`MAX_FREQUENCY` (twice the Nyquist frequency).

``refine=True`` (the default) adds two corrections to these steps, both of the binning, which
ISO 12233:2017 leaves in; ``refine=False`` is the standard's computation as it stands:

- each bin's mean is placed at the mean distance of its pixels (not the bin's centre) and the
  ESF resampled to the quarter-pixel grid: with few rows the pixels of a bin do not spread
  evenly over it, and on a steep edge that offset is noise in the ESF;
- the MTF is also divided by the bin's own response ``sinc(f d)`` (averaging over a bin of
  width ``d`` is a box filter).

On pixel-integrated Gaussian edges (64 rows by 128 columns, 2-10 degrees, sigma 0.3-4 px,
tests/measure/test_sharpness.py) the refined MTF50 is within 1 % of the closed form, the standard's
within 2.5 % (up to 1.3 % low on average at sigma 0.3 px, from the bin's box, and up to 1 %
either way with the phase of so few rows).

Above the Nyquist frequency: the 4x oversampled ESF measures the MTF of the optics and the
pixel aperture before sampling up to :data:`MAX_FREQUENCY`, so a very sharp edge's MTF50 above
:data:`NYQUIST` (0.5 cy/px; a Gaussian PSF with ``sigma`` below about 0.22 px) is measured, not
refused: at sigma 0.15-0.2 px the refined MTF50 is within 0.5 % of the closed form
(tests/measure/test_sharpness.py). It is stated as such (:attr:`EdgeSFR.above_nyquist`; the
terminal and the chart report say so): in the sampled image the detail between the Nyquist
frequency and MTF50 is aliased, folded back below 0.5 cy/px, not resolved.

From the curve: MTF50 and MTF10 (the first frequency where the curve falls to 0.5 and 0.1,
linear interpolation between the two samples around it) and the MTF at half Nyquist (0.25
cy/px).

The standard uncertainty of MTF50 is a parametric bootstrap (JCGM 101 style): the ROI's
per-pixel noise is the standard deviation of its pixels about the binned ESF; a noiseless model
of the ROI (the measured ESF, its plateaus beyond the transition made flat, at each pixel's
distance from the fitted edge) is measured again with :data:`DRAWS` draws of Gaussian noise of
that standard deviation (seeded, ``numpy.random.default_rng(SEED)``), the whole method (edge
location, fit, binning, DFT) run on each draw. ``u_mtf50`` is the root sum of squares of the
draws' standard deviation, of their mean's offset from the model's own MTF50 (the bias noise
gives a first crossing) and of the Hamming window's effect on the model's MTF50 (the window
minus no window: a bias when the ROI is narrow for the blur, 0.8 % at sigma = 4 px in 128
columns). Neither bias is corrected; both are counted. The noise is taken as white and of one
level (signal-dependent shot noise is averaged over the ROI).

An edge that is not fit for the method is refused: :func:`esfr` and :func:`edge_fit` raise
:class:`RefusedEdge` (an :class:`~fidelity.core.errors.InvalidValueError`) whose message names
the problem and whose ``reason`` is one of :data:`REFUSALS`:

``non-finite``
    NaN or Inf in the ROI.
``shape``
    Not a 2-D array (one channel; :func:`esfr_rgb` for RGB).
``too-short``
    Fewer than :data:`MIN_EDGE_PX` pixels along the edge or :data:`MIN_ACROSS_PX` across it.
    These two numbers are this package's floor, not the standard's. An edge
    too short or too little slanted for one whole phase cycle (``rows * tan(angle) < 1``) is
    refused the same way.
``flat``
    No edge: the ROI's profile across the edge has no contrast.
``angle``
    The edge is turned less than :data:`MIN_ANGLE_DEG` from the pixel grid (too few phases:
    :func:`edge_fit` is the fallback there) or more than :data:`MAX_ANGLE_DEG` (near 45 degrees
    the orientation is ambiguous and the square pixel's projection is no longer its width).
``clipped``
    At least :data:`CLIP_FRACTION` of the ROI's pixels at the encoding's maximum
    (``saturation``) or minimum (``black``), as sfrmat's clipping test.
``low-snr``
    The edge's contrast over the per-pixel noise is below :data:`MIN_SNR`.
``low-mtf``
    MTF50 below :data:`MIN_MTF50` cy/px (or no 50 % crossing up to :data:`MAX_FREQUENCY`): the
    edge is too blurred for the ROI (the window and the DFT's resolution bias it).

:func:`edge_fit` is the parametric fallback for an edge nearly aligned with the grid (turned
less than :data:`MIN_ANGLE_DEG`, where the e-SFR's phases are too few): a least-squares fit of
a Gaussian-blurred edge integrated over each pixel's aperture, which gives the Gaussian's
``sigma`` and the MTF50 of ``exp(-2 pi^2 sigma^2 f^2) |sinc(f)|``.

References
----------
ISO 12233:2017, Photography -- Electronic still picture imaging -- Resolution and spatial
frequency responses, Annex D (e-SFR).
P. D. Burns, "Slanted-edge MTF for digital camera and scanner analysis", Proc. IS&T PICS 2000,
135-138; sfrmat3 and sfrmat4 (Burns Digital Imaging).
JCGM 101:2008, Evaluation of measurement data -- Supplement 1 to the GUM -- Propagation of
distributions using a Monte Carlo method.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.core.errors import InvalidValueError, RefusedMeasurement
from fidelity.core.fileio import finite_or_none
from fidelity.core.numeric import median
from fidelity.core.record import record

F64 = NDArray[np.float64]
Orientation = Literal["auto", "vertical", "horizontal"]

#: ESF bins per pixel (ISO 12233: 4x oversampling).
OVERSAMPLING = 4
#: Fewest pixels along the edge (this package's floor, not a number of ISO 12233:2017).
MIN_EDGE_PX = 20
#: Fewest pixels across the edge.
MIN_ACROSS_PX = 16
#: Smallest edge angle (degrees from the pixel grid) the e-SFR accepts.
MIN_ANGLE_DEG = 1.0
#: Largest edge angle (degrees) the e-SFR accepts (45 is the diagonal).
MAX_ANGLE_DEG = 40.0
#: Share of the ROI's pixels at the encoding's maximum or minimum that makes it clipped
#: (sfrmat's clipping test: 0.5 %).
CLIP_FRACTION = 0.005
#: Smallest edge contrast over per-pixel noise.
MIN_SNR = 3.0
#: Smallest MTF50 (cy/px) measured.
MIN_MTF50 = 0.02
#: The reported curve ends here (cy/px; twice Nyquist, as sfrmat reports).
MAX_FREQUENCY = 1.0
#: The Nyquist frequency of the pixel grid (cy/px): an MTF50 above it is stated as aliased
#: (:attr:`EdgeSFR.above_nyquist`).
NYQUIST = 0.5
#: Half the Nyquist frequency (cy/px), where ``mtf_half_nyquist`` is read.
HALF_NYQUIST = 0.25
#: Pixels of the measured ESF kept beyond its 2 % and 98 % points in the bootstrap's model.
PLATEAU_PAD_PX = 3
#: Bootstrap draws of the MTF50 uncertainty.
DRAWS = 40
#: Seed of the bootstrap's generator (the uncertainty is reproducible).
SEED = 20251214
#: Luminance weights of :func:`esfr_rgb` (ITU-R BT.709 / sRGB Y from linear R, G, B).
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
#: The ``reason`` codes of :class:`RefusedEdge`.
REFUSALS: tuple[str, ...] = ("non-finite", "shape", "too-short", "flat", "angle", "clipped",
                             "low-snr", "low-mtf")

ESFR_METHOD = ("ISO 12233:2017 e-SFR: Hamming-windowed derivative centroids, polynomial edge "
               "fit, 4x binned ESF along the edge normal, central-difference LSF, Hamming "
               "window, DFT with the derivative correction")
REFINED_METHOD = "; each bin at its pixels' mean distance, the bin's box response divided out"
BOOTSTRAP_METHOD = ("parametric bootstrap: the noiseless ESF model of the ROI plus Gaussian "
                    "noise of the residuals' standard deviation, the e-SFR repeated per draw")
EDGE_FIT_METHOD = ("erf edge fit: a Gaussian PSF (sigma) integrated over the pixel aperture, "
                   "least squares over the ROI; MTF = exp(-2 pi^2 sigma^2 f^2) |sinc(f)|")


class RefusedEdge(RefusedMeasurement):
    """An ROI the e-SFR (or the edge fit) cannot measure: the message names the problem.

    Parameters
    ----------
    reason
        One of :data:`REFUSALS` (machine-readable).
    message
        The one-line message (``roi: <problem>``).

    Attributes
    ----------
    reason
        One of :data:`REFUSALS`.
    """



@record
class EdgeSFR:
    """The e-SFR of one slanted edge (:func:`esfr`).

    Attributes
    ----------
    frequencies
        Spatial frequencies (cycles per pixel along the edge normal), 0 to
        :data:`MAX_FREQUENCY`, evenly spaced.
    mtf
        The e-SFR at ``frequencies`` (1 at f = 0; unitless).
    mtf50
        First frequency (cy/px) where the e-SFR falls to 0.5 (linear interpolation).
    u_mtf50
        Standard uncertainty (k = 1) of ``mtf50`` (cy/px), :data:`BOOTSTRAP_METHOD`; None
        when no bootstrap was run (``draws=0``) or too few draws could be measured.
    mtf10
        First frequency (cy/px) where the e-SFR falls to 0.1; None if it stays above 0.1 up
        to :data:`MAX_FREQUENCY`.
    mtf_half_nyquist
        The e-SFR at 0.25 cy/px.
    angle
        Edge angle (degrees) from the pixel grid's axis it runs along: from the vertical for a
        vertical edge (positive: the edge moves to larger columns down the rows), from the
        horizontal for a horizontal one (positive: to larger rows along the columns).
    orientation
        ``"vertical"`` or ``"horizontal"``.
    polarity
        ``"rising"`` (dark to light along increasing column, or row for a horizontal edge) or
        ``"falling"``.
    refined
        Whether the binning corrections were applied (``refine`` of :func:`esfr`).
    rows
        Pixels along the edge used (after the cut to whole phase cycles).
    degree
        Degree of the edge-position polynomial.
    contrast
        The ESF's light level minus its dark level (the ROI's units).
    noise
        Per-pixel noise: standard deviation of the pixels about the binned ESF (ROI units).
    snr
        ``contrast / noise`` (inf for a noiseless ROI).
    draws
        Bootstrap draws measured for ``u_mtf50``.
    method
        How the curve was measured (:data:`ESFR_METHOD`).
    """

    frequencies: tuple[float, ...]
    mtf: tuple[float, ...]
    mtf50: float
    u_mtf50: float | None
    mtf10: float | None
    mtf_half_nyquist: float
    angle: float
    orientation: str
    polarity: str
    refined: bool
    rows: int
    degree: int
    contrast: float
    noise: float
    snr: float
    draws: int
    method: str = ESFR_METHOD

    @property
    def above_nyquist(self) -> bool:
        """Whether ``mtf50`` is above :data:`NYQUIST`: the pre-sampling MTF is measured
        there, but the sampled image aliases the detail between 0.5 cy/px and MTF50."""
        return self.mtf50 > NYQUIST

    def to_json(self) -> dict[str, Any]:
        """Field names as keys; non-finite numbers (a noiseless ROI's SNR) as None."""
        return {"frequencies": list(self.frequencies), "mtf": list(self.mtf),
                "mtf50": self.mtf50, "u_mtf50": finite_or_none(self.u_mtf50),
                "mtf10": finite_or_none(self.mtf10), "mtf_half_nyquist": self.mtf_half_nyquist,
                "angle": self.angle, "orientation": self.orientation,
                "polarity": self.polarity, "refined": self.refined, "rows": self.rows,
                "degree": self.degree,
                "contrast": self.contrast, "noise": self.noise,
                "snr": finite_or_none(self.snr), "draws": self.draws, "method": self.method}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EdgeSFR:
        """Inverse of :meth:`to_json` (a None ``snr`` reads as inf)."""
        def opt(key: str) -> float | None:
            v = d.get(key)
            return None if v is None else float(v)
        snr = d.get("snr")
        return cls(tuple(float(f) for f in d["frequencies"]), tuple(float(m) for m in d["mtf"]),
                   float(d["mtf50"]), opt("u_mtf50"), opt("mtf10"),
                   float(d["mtf_half_nyquist"]), float(d["angle"]), str(d["orientation"]),
                   str(d["polarity"]), bool(d["refined"]), int(d["rows"]), int(d["degree"]),
                   float(d["contrast"]),
                   float(d["noise"]), math.inf if snr is None else float(snr), int(d["draws"]),
                   str(d.get("method", ESFR_METHOD)))


@record
class EdgeFit:
    """The parametric edge fit of a nearly grid-aligned edge (:func:`edge_fit`).

    Attributes
    ----------
    sigma
        The Gaussian PSF's standard deviation (pixels), the pixel aperture taken out.
    u_sigma
        Its standard uncertainty (pixels, k = 1) from the fit's covariance (the residuals'
        variance times ``(J^T J)^-1``).
    mtf50
        MTF50 (cy/px) of ``exp(-2 pi^2 sigma^2 f^2) |sinc(f)|``: the Gaussian with the pixel
        aperture, comparable with :attr:`EdgeSFR.mtf50`.
    u_mtf50
        Its standard uncertainty (cy/px), ``|d mtf50 / d sigma| u_sigma``.
    mtf50_optics
        MTF50 (cy/px) of the Gaussian alone, ``sqrt(ln 2 / (2 pi^2)) / sigma``.
    angle
        Edge angle (degrees), as :attr:`EdgeSFR.angle`.
    orientation
        ``"vertical"`` or ``"horizontal"``.
    polarity
        ``"rising"`` or ``"falling"``.
    rows
        Pixels along the edge.
    contrast
        Fitted light level minus dark level (ROI units).
    noise
        RMS residual of the fit (ROI units).
    method
        :data:`EDGE_FIT_METHOD`.
    """

    sigma: float
    u_sigma: float
    mtf50: float
    u_mtf50: float
    mtf50_optics: float
    angle: float
    orientation: str
    polarity: str
    rows: int
    contrast: float
    noise: float
    method: str = EDGE_FIT_METHOD

    @property
    def above_nyquist(self) -> bool:
        """Whether ``mtf50`` is above :data:`NYQUIST` (as :attr:`EdgeSFR.above_nyquist`)."""
        return self.mtf50 > NYQUIST

    def to_json(self) -> dict[str, Any]:
        """Field names as keys; a non-finite uncertainty as None."""
        return {"sigma": self.sigma, "u_sigma": finite_or_none(self.u_sigma),
                "mtf50": self.mtf50, "u_mtf50": finite_or_none(self.u_mtf50),
                "mtf50_optics": self.mtf50_optics, "angle": self.angle,
                "orientation": self.orientation, "polarity": self.polarity, "rows": self.rows,
                "contrast": self.contrast, "noise": self.noise, "method": self.method}


# --------------------------------------------------------------------------------------------
# the steps


def _check_roi(roi: ArrayLike, saturation: float | None, black: float | None,
               orientation: Orientation) -> tuple[F64, str]:
    """The ROI as float64, transposed to a vertical edge, with its orientation; the input
    refusals (shape, non-finite, too short, clipped, flat)."""
    raw = np.asarray(roi)
    if raw.ndim != 2:
        raise RefusedEdge("shape", f"roi: must be a 2-D array (one channel), got shape "
                                   f"{raw.shape}")
    if np.issubdtype(raw.dtype, np.integer):
        info = np.iinfo(raw.dtype)
        saturation = float(info.max) if saturation is None else saturation
        black = float(info.min) if black is None else black
    a = raw.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise RefusedEdge("non-finite", f"roi: {int(np.sum(~np.isfinite(a)))} non-finite "
                                        "values (NaN or Inf)")
    if orientation == "auto":
        across_cols = np.ptp(a.mean(axis=0))
        across_rows = np.ptp(a.mean(axis=1))
        orientation = "horizontal" if across_rows > across_cols else "vertical"
    elif orientation not in ("vertical", "horizontal"):
        raise InvalidValueError(f"{orientation}: unknown orientation; known: auto, "
                                "horizontal, vertical")
    if orientation == "horizontal":
        a = a.T
    rows, cols = a.shape
    if rows < MIN_EDGE_PX or cols < MIN_ACROSS_PX:
        raise RefusedEdge("too-short", f"roi: edge too short: {rows} px along the edge and "
                                       f"{cols} across ({orientation} edge); at least "
                                       f"{MIN_EDGE_PX} along and {MIN_ACROSS_PX} across")
    for limit, name, at in ((saturation, "maximum", a >= (saturation or 0.0)),
                            (black, "minimum", a <= (black or 0.0))):
        if limit is None:
            continue
        share = float(np.mean(at))
        if share >= CLIP_FRACTION:
            raise RefusedEdge("clipped", f"roi: clipped edge: {share:.1%} of the pixels at the "
                                         f"encoding's {name} {limit:g} (limit "
                                         f"{CLIP_FRACTION:.1%})")
    profile = a.mean(axis=0)
    scale = max(1.0, float(np.max(np.abs(a))))
    if float(np.ptp(profile)) <= 1e-12 * scale:
        raise RefusedEdge("flat", "roi: no edge: the profile across the edge is flat")
    return a, orientation


def _polarity(a: F64) -> float:
    """+1 for a rising edge (left darker than right), -1 for a falling one."""
    k = max(2, a.shape[1] // 10)
    return 1.0 if a[:, -k:].mean() >= a[:, :k].mean() else -1.0


def _hamming(x: F64, centre: F64) -> F64:
    """Hamming windows over positions ``x`` (n,), one per centre (rows,): half-width the
    larger distance from the centre to an end (sfrmat's ``ahamming``)."""
    half = np.maximum(centre - x[0], x[-1] - centre)[:, None]
    half = np.maximum(half, 1e-9)
    w = 0.54 + 0.46 * np.cos(np.pi * (x[None, :] - centre[:, None]) / half)
    return np.asarray(w, dtype=np.float64)


@lru_cache(maxsize=64)
def _middle_window(rows: int, cols: int) -> F64:
    """The :func:`_hamming` windows of the first pass of :func:`_edge_locations` (every row
    centred on the middle of its ``cols - 1`` differences), read-only: made once per ROI shape
    (the bootstrap's draws share it)."""
    x = np.arange(cols - 1, dtype=np.float64) + 0.5
    w = _hamming(x, np.full(rows, 0.5 * (x[0] + x[-1])))
    w.flags.writeable = False
    return w


@lru_cache(maxsize=64)
def _lsf_window(n: int, peak: int) -> F64:
    """The :func:`_hamming` window of an ``n``-bin LSF centred on bin ``peak``, read-only
    (the bootstrap's draws mostly share it)."""
    w: F64 = _hamming(np.arange(n, dtype=np.float64), np.array([float(peak)]))[0]
    w.flags.writeable = False
    return w


def _fit_rows(r: F64, loc: F64, deg: int) -> F64:
    """Least-squares polynomials of degree ``deg`` (coefficients lowest first) of each row of
    ``loc`` (d, rows) against ``r`` (rows,), over its finite entries (the others are left
    out): (d, deg + 1). Normal equations in ``u = (r - m) / s`` (m the centre, s the
    half-range of ``r``: a well-conditioned basis for deg <= 2), mapped back to powers of r;
    the same polynomial as NumPy's ``polyfit`` of the finite points, to rounding (a test).
    A row with fewer than ``deg + 1`` distinct points gives NaN."""
    m = 0.5 * (float(r[0]) + float(r[-1]))
    s = max(0.5 * abs(float(r[-1]) - float(r[0])), 1.0)
    u = (r - m) / s
    powers = u[:, None] ** np.arange(deg + 1)  # (rows, deg + 1)
    ok = np.isfinite(loc)
    w = ok.astype(np.float64)
    y = np.where(ok, loc, 0.0)
    normal = np.einsum("dr,rk,rj->dkj", w, powers, powers)
    rhs = np.einsum("dr,rk->dk", w * y, powers)
    coef_u = np.full(rhs.shape, np.nan)
    solvable = np.abs(np.linalg.det(normal)) > 1e-12 * np.maximum(
        1.0, np.prod(np.diagonal(normal, axis1=1, axis2=2), axis=1))
    if solvable.any():
        coef_u[solvable] = np.linalg.solve(normal[solvable], rhs[solvable][..., None])[..., 0]
    # p(r) = sum_k b_k ((r - m) / s)^k: the coefficients of powers of r
    basis = np.zeros((deg + 1, deg + 1))
    for k in range(deg + 1):
        term = np.polynomial.polynomial.polypow([-m / s, 1.0 / s], k)
        basis[k, :term.size] = term
    return np.asarray(coef_u @ basis, dtype=np.float64)


def _poly_rows(r: F64, coef: F64) -> F64:
    """Each polynomial of ``coef`` (d, deg + 1), lowest first, at ``r`` (rows,): (d, rows)."""
    out = np.zeros((coef.shape[0], r.size))
    for c in coef.T[::-1]:  # Horner
        out = out * r + c[:, None]
    return out


def _edge_stack(a: F64, sign: F64, degree: int) -> tuple[F64, F64, F64, NDArray[np.int64]]:
    """:func:`_edge_locations` of each ROI of a stack ``a`` (d, rows, cols) with polarities
    ``sign`` (d,) at once: the locations (d, rows), the ``degree`` and first-order fits (d,
    deg + 1), (d, 2), and per ROI the rows without an edge in the pass whose fit it lacked
    points for (-1: fitted)."""
    d_, rows, cols = a.shape
    d = np.diff(a, axis=-1) * sign[:, None, None]
    x = np.arange(cols - 1, dtype=np.float64) + 0.5
    r = np.arange(rows, dtype=np.float64)
    need = max(degree + 2, MIN_EDGE_PX // 2)
    missing = np.full(d_, -1, dtype=np.int64)

    def centroids(window: F64) -> F64:
        wd = window * d
        total = wd.sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            loc = (wd * x).sum(axis=-1) / total
        ok = (total > 0) & np.isfinite(loc) & (loc >= x[0]) & (loc <= x[-1])
        return np.where(ok, loc, np.nan)

    def fit(loc: F64, deg: int) -> F64:
        found = np.isfinite(loc).sum(axis=-1)
        short = (found < need) & (missing < 0)
        missing[short] = rows - found[short]
        return _fit_rows(r, loc, deg)

    loc = centroids(_middle_window(rows, cols))
    coef = fit(loc, degree)
    centre = np.clip(_poly_rows(r, np.nan_to_num(coef)), x[0], x[-1])  # (d, rows)
    half = np.maximum(np.maximum(centre - x[0], x[-1] - centre), 1e-9)[..., None]
    window = 0.54 + 0.46 * np.cos(np.pi * (x - centre[..., None]) / half)  # _hamming's
    loc = centroids(window)
    coef = fit(loc, degree)
    line = coef if degree == 1 else fit(loc, 1)  # degree 1: the same fit
    missing[(missing < 0) & ~np.all(np.isfinite(line), axis=-1)] = rows
    return loc, coef, line, missing


def _edge_locations(a: F64, sign: float, degree: int) -> tuple[F64, F64, F64]:
    """Per-row edge locations (column coordinate, NaN where a row has no edge), the
    ``degree`` fit and the first-order fit (polynomial coefficients, lowest first, of the
    column against the row index): two centroid passes, the second with each row's Hamming
    window centred on the first fit (sfrmat)."""
    loc, coef, line, missing = _edge_stack(a[None], np.array([sign]), degree)
    if missing[0] >= 0:
        raise RefusedEdge("flat", f"roi: no edge found in {int(missing[0])} of {a.shape[0]} "
                                  "rows")
    return loc[0], coef[0], line[0]


@record
class _Core:
    frequencies: F64
    mtf: F64
    slope: float
    rows: int
    start: int
    coef: F64
    esf_pos: F64
    esf: F64
    contrast: float
    noise: float


def _core(a: F64, degree: int, check: bool, strict: bool = True,
          window: bool = True) -> _Core:
    """The e-SFR of a vertical-ish edge (steps 2-8); ``check`` raises the refusals that need
    the fit (angle, phase cycles, SNR)."""
    sign = _polarity(a)
    _loc, coef, line = _edge_locations(a, sign, degree)
    return _core_fitted(a, sign, coef, line, check, strict, window)


def _core_fitted(a: F64, sign: float, coef: F64, line: F64, check: bool, strict: bool,
                 window: bool) -> _Core:
    """:func:`_core` from the edge's fits (:func:`_edge_locations`): steps 3-8."""
    rows_all, cols = a.shape
    slope = float(line[1])
    angle = math.degrees(math.atan(abs(slope)))
    if check and not MIN_ANGLE_DEG <= angle <= MAX_ANGLE_DEG:
        raise RefusedEdge("angle", f"roi: edge angle {angle:.2f} deg is outside "
                                   f"[{MIN_ANGLE_DEG:g}, {MAX_ANGLE_DEG:g}] deg from the pixel "
                                   "grid" + (" (edge_fit measures a grid-aligned edge)"
                                             if angle < MIN_ANGLE_DEG else ""))
    cycles = math.floor(rows_all * abs(slope))
    if cycles < 1:
        raise RefusedEdge("too-short", f"roi: edge too short for its angle: {rows_all} rows "
                                       f"at {angle:.2f} deg make {rows_all * abs(slope):.2f} "
                                       "phase cycles, fewer than one")
    rows = min(rows_all, max(MIN_EDGE_PX // 2, int(round(cycles / abs(slope)))))
    start = (rows_all - rows) // 2
    r = np.arange(start, start + rows, dtype=np.float64)
    c = np.arange(cols, dtype=np.float64)
    xe = np.polynomial.polynomial.polyval(r, coef)
    local = np.polynomial.polynomial.polyval(r, np.polynomial.polynomial.polyder(coef))
    cos = 1.0 / np.sqrt(1.0 + local * local)
    dist = (c[None, :] - xe[:, None]) * cos[:, None]
    values = a[start:start + rows]
    step = 1.0 / OVERSAMPLING
    k = np.floor(dist / step + 0.5).astype(np.int64)
    kmin = int(k.min())
    idx = (k - kmin).ravel()
    counts = np.bincount(idx).astype(np.float64)
    sums = np.bincount(idx, weights=values.ravel())
    pos = (np.arange(counts.size, dtype=np.float64) + kmin) * step
    filled = counts > 0
    means = sums[filled] / counts[filled]
    if strict:
        esf = np.interp(pos, pos[filled], means)
    else:
        # each bin's mean at the mean distance of its pixels, resampled to the bin grid
        at = np.bincount(idx, weights=dist.ravel())[filled] / counts[filled]
        esf = np.interp(pos, at, means)
    # noise: the pixels about the binned ESF
    resid = values.ravel() - np.interp(dist.ravel(), pos, esf)
    dof = max(1, resid.size - int(filled.sum()))
    noise = float(math.sqrt(float(np.sum(resid * resid)) / dof))
    tail = max(2, esf.size // 10)
    lo, hi = median(esf[:tail]), median(esf[-tail:])
    contrast = abs(hi - lo)
    if check:
        snr = contrast / noise if noise > 0 else math.inf
        if snr < MIN_SNR:
            raise RefusedEdge("low-snr", f"roi: edge contrast over noise {snr:.2f} is below "
                                         f"{MIN_SNR:g} (contrast {contrast:.4g}, noise "
                                         f"{noise:.4g})")
    lsf = np.empty_like(esf)
    lsf[1:-1] = 0.5 * (esf[2:] - esf[:-2])
    lsf[0], lsf[-1] = lsf[1], lsf[-2]
    lsf *= sign
    n = lsf.size
    peak = -kmin  # the bin of distance 0: the fitted edge
    w = _lsf_window(n, peak) if window else np.ones(n)
    nfft = 1 << max(1, math.ceil(math.log2(2 * n)))
    spectrum = np.abs(np.fft.rfft(lsf * w, nfft))
    if not spectrum[0] > 0:
        raise RefusedEdge("flat", "roi: no edge: the line spread function sums to zero")
    freq, keep, derivative, box = _frequency_grid(nfft)
    mtf = spectrum[keep] / spectrum[0] / derivative
    if not strict:
        mtf = mtf / box
    return _Core(freq, np.asarray(mtf, dtype=np.float64), slope, rows, start, coef, pos, esf,
                 contrast, noise)


@lru_cache(maxsize=16)
def _frequency_grid(nfft: int) -> tuple[F64, NDArray[np.bool_], F64, F64]:
    """The frequencies (cy/px) of an ``nfft``-point spectrum of the oversampled LSF up to
    :data:`MAX_FREQUENCY`, which of the spectrum's bins they are, and the two responses
    :func:`_core` divides out at them: the central difference's (sinc of twice the bin
    width) and the bin's box (sinc of the bin width). Read-only; made once per ``nfft`` (the
    bootstrap's draws share it)."""
    step = 1.0 / OVERSAMPLING
    every = np.fft.rfftfreq(nfft, d=step)
    keep: NDArray[np.bool_] = every <= MAX_FREQUENCY + 1e-12
    freq: F64 = np.asarray(every[keep], dtype=np.float64)
    derivative: F64 = np.asarray(np.sinc(2.0 * freq * step), dtype=np.float64)
    box: F64 = np.asarray(np.sinc(freq * step), dtype=np.float64)
    for a in (freq, keep, derivative, box):
        a.flags.writeable = False
    return freq, keep, derivative, box


def _crossing(freq: F64, mtf: F64, level: float) -> float | None:
    """First frequency where ``mtf`` falls to ``level`` (linear interpolation)."""
    below = np.nonzero(mtf[1:] <= level)[0]
    if below.size == 0:
        return None
    i = int(below[0]) + 1
    f0, f1, m0, m1 = freq[i - 1], freq[i], mtf[i - 1], mtf[i]
    return float(f1 if m0 == m1 else f0 + (m0 - level) * (f1 - f0) / (m0 - m1))


def _model(a: F64, core: _Core) -> F64:
    """The noiseless ROI the ESF predicts (every row, each pixel at its distance)."""
    rows, cols = a.shape
    r = np.arange(rows, dtype=np.float64)
    xe = np.polynomial.polynomial.polyval(r, core.coef)
    local = np.polynomial.polynomial.polyval(r, np.polynomial.polynomial.polyder(core.coef))
    cos = 1.0 / np.sqrt(1.0 + local * local)
    dist = (np.arange(cols, dtype=np.float64)[None, :] - xe[:, None]) * cos[:, None]
    return np.asarray(np.interp(dist, core.esf_pos, _smooth_esf(core.esf)), dtype=np.float64)


def _smooth_esf(esf: F64) -> F64:
    """The ESF with its noise-only plateaus made flat: outside the transition (from 2 % to
    98 % of the contrast, widened by :data:`PLATEAU_PAD_PX` on each side) each end is set to
    its plateau's median. The bootstrap's model: a noisy model would carry the measurement's
    own ripple into every draw."""
    tail = max(2, esf.size // 10)
    lo, hi = median(esf[:tail]), median(esf[-tail:])
    if hi == lo:
        return esf
    en = (esf - lo) / (hi - lo)
    inside = np.nonzero((en >= 0.02) & (en <= 0.98))[0]
    if inside.size == 0:
        return esf
    pad = PLATEAU_PAD_PX * OVERSAMPLING
    i0, i1 = max(0, int(inside[0]) - pad), min(esf.size, int(inside[-1]) + pad + 1)
    out = esf.copy()
    out[:i0], out[i1:] = lo, hi
    return out


#: Most pixel values of bootstrap draws whose edges are fitted together
#: (:func:`_bootstrap_mtf50`): 2 million, 16 MB a stack.
BOOTSTRAP_STACK_VALUES = 2_000_000


def _bootstrap_mtf50(model: F64, noise: float, rng: np.random.Generator, draws: int,
                     degree: int, strict: bool) -> list[float]:
    """The MTF50 of ``draws`` noisy copies of ``model`` (Gaussian, σ ``noise``, drawn from
    ``rng`` one copy after another), each measured as :func:`_core` measures (a draw it
    refuses, or without a crossing, left out): their edges fitted in stacks of up to
    :data:`BOOTSTRAP_STACK_VALUES` values (:func:`_edge_stack`), the rest per draw."""
    rows, cols = model.shape
    per = max(1, BOOTSTRAP_STACK_VALUES // model.size)
    k = max(2, cols // 10)
    found: list[float] = []
    for first in range(0, draws, per):
        stack = np.stack([model + rng.normal(0.0, noise, model.shape)
                          for _ in range(min(per, draws - first))])
        signs = np.where(stack[:, :, -k:].mean(axis=(1, 2)) >= stack[:, :, :k].mean(axis=(1, 2)),
                         1.0, -1.0)  # _polarity of each
        _loc, coef, line, missing = _edge_stack(stack, signs, degree)
        for i in np.flatnonzero(missing < 0):
            try:
                c = _core_fitted(stack[i], float(signs[i]), coef[i], line[i], check=False,
                                 strict=strict, window=True)
            except RefusedEdge:
                continue
            m = _crossing(c.frequencies, c.mtf, 0.5)
            if m is not None:
                found.append(m)
    return found


def esfr(roi: ArrayLike, *, orientation: Orientation = "auto", degree: int = 1,
         saturation: float | None = None, black: float | None = None, refine: bool = True,
         draws: int = DRAWS, seed: int = SEED) -> EdgeSFR:
    """The ISO 12233:2017 e-SFR of one slanted-edge region of interest (module docstring).

    Parameters
    ----------
    roi
        The region of interest, shape ``(rows, cols)``: one channel of LINEAR values (any
        unit; an encoded image must be decoded first), one edge crossing it from one side to
        the opposite one, dark on one side and light on the other (either polarity).
    orientation
        ``"vertical"`` (the transition runs along the columns), ``"horizontal"`` (along the
        rows: the ROI is transposed) or ``"auto"``: the axis along which the ROI's mean profile
        changes more.
    degree
        Degree of the polynomial of edge position against row: 1 (ISO 12233:2017) or 2
        (a curved edge, sfrmat4).
    saturation
        The encoding's maximum (1.0 for a display-referred float image, 255 for 8-bit codes):
        an ROI with :data:`CLIP_FRACTION` of its pixels at or above it is refused. None: the
        dtype's maximum for integer arrays, no test for floats (scene-linear values may
        exceed 1).
    black
        The encoding's minimum, tested the same way (None: the dtype's minimum for integer
        arrays, no test for floats).
    refine
        True: the two binning corrections of the module docstring (each bin at its pixels'
        mean distance; the bin's box response divided out). False: ISO 12233:2017 as it
        stands.
    draws
        Bootstrap draws of the MTF50 uncertainty (0: none, ``u_mtf50`` None).
    seed
        Seed of the bootstrap's generator.

    Returns
    -------
    EdgeSFR
        The curve (0 to :data:`MAX_FREQUENCY` cy/px), MTF50 with its standard uncertainty,
        MTF10, the MTF at half Nyquist, the edge's angle, orientation and polarity, the rows
        used and the ROI's noise.

    Raises
    ------
    RefusedEdge
        An ROI the method cannot measure, with a reason of :data:`REFUSALS` (module
        docstring): non-finite values, not 2-D, too short, flat, angle below
        :data:`MIN_ANGLE_DEG` or above :data:`MAX_ANGLE_DEG`, clipped, SNR below
        :data:`MIN_SNR`, MTF50 below :data:`MIN_MTF50`.
    fidelity.core.errors.InvalidValueError
        An unknown ``orientation``, a ``degree`` other than 1 or 2, a negative ``draws``.

    References
    ----------
    ISO 12233:2017, Annex D; P. D. Burns, sfrmat3/sfrmat4; JCGM 101:2008 (the bootstrap).
    """
    if degree not in (1, 2):
        raise InvalidValueError(f"{degree}: edge-fit degree must be 1 or 2")
    if draws < 0:
        raise InvalidValueError(f"{draws}: bootstrap draws must be >= 0")
    a, orient = _check_roi(roi, saturation, black, orientation)
    core = _core(a, degree, check=True, strict=not refine)
    mtf50 = _crossing(core.frequencies, core.mtf, 0.5)
    if mtf50 is None or mtf50 < MIN_MTF50:
        shown = "none up to 1 cy/px" if mtf50 is None else f"{mtf50:.4f} cy/px"
        raise RefusedEdge("low-mtf", f"roi: MTF50 {shown} is below {MIN_MTF50:g} cy/px "
                                     "(edge too blurred for the ROI)")
    u: float | None = None
    done = 0
    if draws > 0:
        rng = np.random.default_rng(seed)
        model = _model(a, core)
        found = _bootstrap_mtf50(model, core.noise, rng, draws, degree, not refine)
        done = len(found)
        if done >= max(2, draws // 2):
            # the draws' spread; their mean's offset from the noiseless model's MTF50 (the
            # noise's bias of a first crossing); the window's effect on the model's MTF50
            # (a narrow ROI for its blur): neither corrected, both counted in u
            centre = plain = None
            try:
                c = _core(model, degree, check=False, strict=not refine)
                centre = _crossing(c.frequencies, c.mtf, 0.5)
                c = _core(model, degree, check=False, strict=not refine, window=False)
                plain = _crossing(c.frequencies, c.mtf, 0.5)
            except RefusedEdge:
                pass
            bias = 0.0 if centre is None else float(np.mean(found)) - centre
            windowed = 0.0 if centre is None or plain is None else centre - plain
            u = float(math.sqrt(float(np.var(found, ddof=1)) + bias * bias
                                + windowed * windowed))
    sign = _polarity(a)
    angle = math.degrees(math.atan(core.slope))
    half = float(np.interp(HALF_NYQUIST, core.frequencies, core.mtf))
    return EdgeSFR(
        frequencies=tuple(float(f) for f in core.frequencies),
        mtf=tuple(float(m) for m in core.mtf), mtf50=mtf50, u_mtf50=u,
        mtf10=_crossing(core.frequencies, core.mtf, 0.1), mtf_half_nyquist=half, angle=angle,
        orientation=orient, polarity="rising" if sign > 0 else "falling", refined=refine,
        rows=core.rows, degree=degree, contrast=core.contrast, noise=core.noise,
        snr=core.contrast / core.noise if core.noise > 0 else math.inf, draws=done,
        method=ESFR_METHOD + (REFINED_METHOD if refine else ""))


def esfr_rgb(roi: ArrayLike, **options: Any) -> dict[str, EdgeSFR]:
    """The e-SFR of each channel of an RGB region of interest and of its luminance.

    Parameters
    ----------
    roi
        Shape ``(rows, cols, 3)``: LINEAR R, G, B (any unit).
    **options
        Passed to :func:`esfr` (``orientation``, ``degree``, ``saturation``, ``black``,
        ``draws``, ``seed``).

    Returns
    -------
    dict
        ``{"R", "G", "B", "Y"}`` to :class:`EdgeSFR`, Y the luminance
        ``0.2126 R + 0.7152 G + 0.0722 B`` (:data:`LUMINANCE_WEIGHTS`).

    Raises
    ------
    RefusedEdge
        Not ``(rows, cols, 3)``, or a channel :func:`esfr` refuses (the message names the
        channel).

    References
    ----------
    ISO 12233:2017, Annex D (the luminance record of a colour image).
    """
    a = np.asarray(roi)
    if a.ndim != 3 or a.shape[2] != 3:
        raise RefusedEdge("shape", f"roi: must have shape (rows, cols, 3), got {a.shape}")
    wr, wg, wb = LUMINANCE_WEIGHTS
    f = a.astype(np.float64)
    channels = {"R": a[..., 0], "G": a[..., 1], "B": a[..., 2],
                "Y": wr * f[..., 0] + wg * f[..., 1] + wb * f[..., 2]}
    out: dict[str, EdgeSFR] = {}
    for name, channel in channels.items():
        try:
            out[name] = esfr(channel, **options)
        except RefusedEdge as e:
            raise RefusedEdge(e.reason, f"{name} channel {e}") from e
    return out


# --------------------------------------------------------------------------------------------
# the parametric fallback


def gaussian_mtf50(sigma: float) -> float:
    """MTF50 (cy/px) of a Gaussian PSF with the pixel aperture,
    ``exp(-2 pi^2 sigma^2 f^2) |sinc(f)|`` = 0.5, by root finding.

    Parameters
    ----------
    sigma
        The Gaussian's standard deviation (pixels), >= 0.

    Returns
    -------
    float
        The frequency (cy/px) in (0, 0.61) where the product is 0.5 (0.6034 for
        ``sigma = 0``).

    Raises
    ------
    fidelity.core.errors.InvalidValueError
        ``sigma`` negative or not finite.

    References
    ----------
    ISO 12233:2017 (MTF50); the pixel aperture's MTF is ``|sinc(f)|``.
    """
    if not (math.isfinite(sigma) and sigma >= 0):
        raise InvalidValueError(f"{sigma}: sigma must be finite and >= 0")

    def g(f: float) -> float:
        sinc = math.sin(math.pi * f) / (math.pi * f)
        return math.exp(-2.0 * math.pi ** 2 * sigma ** 2 * f * f) * sinc - 0.5

    # bisection (g falls from 0.5 to below 0 on (0, 0.99)): no scipy to import
    lo, hi = 1e-9, 0.99
    while hi - lo > 1e-12:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


#: Coefficients of the complementary error function's rational approximation (W. J. Cody's
#: Chebyshev fit as Numerical Recipes' ``erfcc``: fractional error below 1.2e-7 everywhere).
_ERFC = (-1.26551223, 1.00002368, 0.37409196, 0.09678418, -0.18628806, 0.27886807,
         -1.13520398, 1.48851587, -0.82215223, 0.17087277)


def _ndtr(z: F64) -> F64:
    """The standard normal CDF ``Phi(z)`` (numpy only: ``erfc`` to 1.2e-7 relative)."""
    x = np.abs(z) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.5 * x)
    poly = np.zeros_like(t)
    for c in reversed(_ERFC):
        poly = poly * t + c
    erfc = t * np.exp(-x * x + poly)
    return np.asarray(np.where(z >= 0, 1.0 - 0.5 * erfc, 0.5 * erfc), dtype=np.float64)


def _least_squares(residuals: Any, p0: F64, lower: F64, upper: F64,
                   iterations: int = 40, analytic: Any = None) -> tuple[F64, F64, F64]:
    """Levenberg-Marquardt within bounds (each step clipped to them), the Jacobian
    ``analytic(p)`` or by forward differences: ``(p, residuals, jacobian)`` at the solution."""
    def jacobian(p: F64, r: F64) -> F64:
        if analytic is not None:
            out: F64 = analytic(p)
            return out
        cols = []
        for k in range(p.size):
            h = 1e-7 * max(abs(float(p[k])), 1e-3)
            q = p.copy()
            q[k] = q[k] + h if q[k] + h <= upper[k] else q[k] - h
            cols.append((residuals(q) - r) / (q[k] - p[k]))
        return np.stack(cols, axis=1)

    p = np.clip(np.asarray(p0, np.float64), lower, upper)
    r = residuals(p)
    cost = float(r @ r)
    lam = 1e-3
    jac = jacobian(p, r)
    for _ in range(iterations):
        a = jac.T @ jac
        g = jac.T @ r
        improved = done = False
        for _ in range(12):
            try:
                step = np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-30), -g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            q = np.clip(p + step, lower, upper)
            rq = residuals(q)
            cq = float(rq @ rq)
            if cq <= cost:
                improved = True
                done = cost - cq <= 1e-7 * cost or bool(np.all(
                    np.abs(q - p) <= 1e-8 * (np.abs(p) + 1e-8)))
                p, r, cost = q, rq, cq
                lam = max(lam / 10.0, 1e-12)
                break
            lam *= 10.0
        if not improved:
            break
        jac = jacobian(p, r)
        if done:
            break
    return p, r, jac


def _pixel_phi(t: F64, sigma: float, width: float) -> F64:
    """Mean of the normal CDF ``Phi(u / sigma)`` over ``u`` in ``[t - width/2, t + width/2]``
    (the pixel aperture along the normal), closed form by ``G(z) = z Phi(z) + phi(z)``."""
    def g(z: F64) -> F64:
        return np.asarray(z * _ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi),
                          dtype=np.float64)

    hi = (t + 0.5 * width) / sigma
    lo = (t - 0.5 * width) / sigma
    return np.asarray(sigma * (g(hi) - g(lo)) / width, dtype=np.float64)


def edge_fit(roi: ArrayLike, *, orientation: Orientation = "auto",
             saturation: float | None = None, black: float | None = None) -> EdgeFit:
    """Fit a Gaussian-blurred edge to a nearly grid-aligned edge: the fallback of
    :func:`esfr` where no edge is turned at least :data:`MIN_ANGLE_DEG` from the grid.

    The model of each pixel ``(row, col)``: ``lo + (hi - lo) * P``, where ``P`` is the normal
    CDF ``Phi(s / sigma)`` averaged over the pixel's aperture along the edge normal (closed
    form), ``s = (col - x0 - slope * row) cos(atan(slope))`` its distance from the edge.
    Least squares over every pixel of the ROI in the five parameters ``lo, hi, x0, slope,
    sigma`` (Levenberg-Marquardt, steps clipped to the bounds, ``sigma`` bounded to
    [0.01, cols]; numpy only, so that an audit imports no scipy); the
    standard uncertainties from the covariance ``s^2 (J^T J)^-1``.

    Parameters
    ----------
    roi
        Shape ``(rows, cols)``: one channel of LINEAR values, one edge across it (either
        polarity, any angle below :data:`MAX_ANGLE_DEG`; meant for angles below
        :data:`MIN_ANGLE_DEG`).
    orientation
        As :func:`esfr`.
    saturation
        As :func:`esfr`.
    black
        As :func:`esfr`.

    Returns
    -------
    EdgeFit
        The Gaussian's ``sigma`` (pixels) with its uncertainty, the MTF50 of the Gaussian with
        the pixel aperture (comparable with :func:`esfr`'s) and of the Gaussian alone.

    Raises
    ------
    RefusedEdge
        Non-finite values, not 2-D, too short, flat, clipped (as :func:`esfr`), an edge-to-
        noise ratio below :data:`MIN_SNR` or an MTF50 below :data:`MIN_MTF50`.

    References
    ----------
    ISO 12233:2017 (MTF50); the erf edge model: the edge spread function of a Gaussian PSF
    is ``Phi(x / sigma)``.
    """
    a, orient = _check_roi(roi, saturation, black, orientation)
    sign = _polarity(a)
    rows, cols = a.shape
    _loc, _coef, line = _edge_locations(a, sign, 1)
    k = max(2, cols // 10)
    left, right = float(a[:, :k].mean()), float(a[:, -k:].mean())
    lo0, hi0 = (left, right) if sign > 0 else (right, left)
    r = np.arange(rows, dtype=np.float64)[:, None]
    c = np.arange(cols, dtype=np.float64)[None, :]

    def model(p: F64) -> F64:
        lo, hi, x0, slope, sigma = p
        cos = 1.0 / math.sqrt(1.0 + slope * slope)
        s = sign * (c - x0 - slope * r) * cos
        return np.asarray(lo + (hi - lo) * _pixel_phi(s, sigma, cos), dtype=np.float64)

    def residuals(p: F64) -> F64:
        return (model(p) - a).ravel()

    def jacobian(p: F64) -> F64:
        # P = sigma (G(z+) - G(z-)) / w, z+- = (s +- w/2) / sigma, G' = Phi, G - z Phi = phi
        lo, hi, x0, slope, sigma = p
        cos = 1.0 / math.sqrt(1.0 + slope * slope)
        w = cos
        d = c - x0 - slope * r
        s = sign * d * cos
        zp, zm = (s + 0.5 * w) / sigma, (s - 0.5 * w) / sigma
        cp, cm = _ndtr(zp), _ndtr(zm)
        gp = zp * cp + np.exp(-0.5 * zp * zp) / math.sqrt(2.0 * math.pi)
        gm = zm * cm + np.exp(-0.5 * zm * zm) / math.sqrt(2.0 * math.pi)
        big_p = sigma * (gp - gm) / w
        dp_ds = (cp - cm) / w
        dp_dsigma = ((gp - zp * cp) - (gm - zm * cm)) / w
        dp_dw = -big_p / w + (cp + cm) / (2.0 * w)
        dcos = -slope * cos ** 3
        ds_dslope = sign * (-r * cos + d * dcos)
        k = hi - lo
        cols = [1.0 - big_p, big_p, k * dp_ds * (-sign * cos),
                k * (dp_ds * ds_dslope + dp_dw * dcos), k * dp_dsigma]
        return np.stack([np.broadcast_to(col, a.shape).ravel() for col in cols], axis=1)

    p0 = np.array([lo0, hi0, float(line[0]), float(line[1]), 1.0])
    lower = np.array([-np.inf, -np.inf, -cols, -1.0, 0.01])
    upper = np.array([np.inf, np.inf, 2.0 * cols, 1.0, float(cols)])
    p, res, jac = _least_squares(residuals, p0, lower, upper, analytic=jacobian)
    dof = max(1, res.size - p.size)
    s2 = float(res @ res) / dof
    cov = np.linalg.pinv(jac.T @ jac) * s2
    sigma = float(p[4])
    u_sigma = float(math.sqrt(max(0.0, float(cov[4, 4]))))
    contrast = abs(float(p[1] - p[0]))
    noise = math.sqrt(s2)
    snr = contrast / noise if noise > 0 else math.inf
    if snr < MIN_SNR:
        raise RefusedEdge("low-snr", f"roi: edge contrast over noise {snr:.2f} is below "
                                     f"{MIN_SNR:g}")
    mtf50 = gaussian_mtf50(sigma)
    if mtf50 < MIN_MTF50:
        raise RefusedEdge("low-mtf", f"roi: MTF50 {mtf50:.4f} cy/px is below {MIN_MTF50:g} "
                                     "cy/px (edge too blurred)")
    h = max(1e-4, 1e-3 * sigma)
    slope_mtf = (gaussian_mtf50(sigma + h) - gaussian_mtf50(max(0.0, sigma - h))) / (
        sigma + h - max(0.0, sigma - h))
    return EdgeFit(sigma=sigma, u_sigma=u_sigma, mtf50=mtf50, u_mtf50=abs(slope_mtf) * u_sigma,
                   mtf50_optics=math.sqrt(math.log(2.0) / (2.0 * math.pi ** 2)) / sigma,
                   angle=math.degrees(math.atan(float(p[3]))), orientation=orient,
                   polarity="rising" if sign > 0 else "falling", rows=rows, contrast=contrast,
                   noise=noise)
