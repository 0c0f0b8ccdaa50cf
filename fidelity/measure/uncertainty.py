"""The standard uncertainty of a chart ΔE00 (GUM style): an :class:`UncertaintyBudget`.

The chart ΔE (mean ΔE00 over the patches) is a function ``f`` of the patch means. Each source of
uncertainty is a component whose standard uncertainty (in ΔE00) is obtained by propagating the
uncertainty of the inputs through ``f`` with a Monte Carlo method (JCGM 101:2008, "GUM
Supplement 1"): :data:`DRAWS` draws with the seeded generator ``numpy.random.default_rng(SEED)``,
the component's standard uncertainty the sample standard deviation of ``f`` over the draws.
Components, each evaluated with the others held at their measured values:

``pixel noise`` (Type A)
    Each patch mean's covariance from its own window: the sample covariance of the pixels over
    ``n`` (a plain mean: the audit of an image, in linear light; where a window spans
    enough of the image's blocks, the mean's covariance from its block means instead,
    :func:`block_mean_covariance`, as neighbouring pixels' errors are alike: JPEG blocks,
    demosaicing, denoising; their channels' correlation is the block means', not the
    pixels'), or the Tukey-McLaughlin
    winsorised covariance over ``(1 - 2 g)^2 n`` (a ``g``-trimmed mean: a camera render's
    patch sampling). Means drawn from the normal distribution with that covariance (the
    analytic standard error, propagated by Monte Carlo). An auto exposure is refitted on every
    draw, so the noise of the neutral patches reaches every patch as it does in the
    measurement. A patch with fewer than :data:`MIN_NOISE_PIXELS` valid pixels cannot estimate
    its own noise: it is given the largest per-pixel covariance of the other patches (a
    conservative Type B value) and named in ``notes``; without any such patch, a rectangular
    distribution over the whole [0, 1] range of each channel.
``rounding`` (Type B)
    Integer pixel codes: each patch channel's mean carries the rounding error its codes'
    spread leaves (:func:`rounding_residual`): the rounding error of one code, rectangular
    over ``±q/2`` (JCGM 100 F.2.2.1), when the pixels all hold one code, less as noise dithers
    them, none once they vary by half a step ``q``.
``placement`` (Type B, images only)
    The four corner centres jittered by the finder's placement uncertainty (normal, per axis:
    the refinement's RMS residual over √2; corners given by the user or found without
    refinement: a rectangular half-pixel, 1/√12 px), the windows located again and the chart
    measured again, :data:`PLACEMENT_DRAWS` draws. A render's windows are those of its layout:
    no placement uncertainty.
``exposure normalisation`` (Type A, auto exposure only)
    The exposure is the mean of the neutral patches' log2 luminance ratios; their spread gives
    its standard error ``s / √k`` (``k`` neutral patches), propagated through ``f``. Fixed
    exposures (and renders) have none.

The combined standard uncertainty is the root sum of squares (the components taken as
uncorrelated, JCGM 100 5.1.2); the budget states the coverage factor ``k`` = 1. Every value is
finite: a noiseless float render has zero for noise and rounding, never NaN.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour import colorimetry as cm
from fidelity.core.record import record

F64 = NDArray[np.float64]

#: Monte Carlo draws of each propagated component.
DRAWS = 400
#: Draws of the jittered corners (each re-locates and re-measures the chart).
PLACEMENT_DRAWS = 24
#: Seed of the generator of every draw (the budget is reproducible).
SEED = 20251125
#: Fewest valid pixels a patch needs to estimate its own noise.
MIN_NOISE_PIXELS = 3
#: Side (px) of the image's blocks whose means show noise correlated between neighbouring
#: pixels (:func:`block_design_effect`): a 4:2:0 JPEG's minimum coded unit, over which its
#: chroma DCT block (and the DC quantisation of its luma blocks) spreads an error alike.
BLOCK_PX = 16
#: Fewest blocks a window must touch for their means to estimate its design effect.
MIN_BLOCKS = 6
#: Most pixels of a window its spread, design effect and code statistics are computed from
#: (:func:`block_sample`): 128 whole :data:`BLOCK_PX`-square blocks, a design effect within
#: about ``sqrt(2 / 127)`` = 13 % (relative standard error of the variance of the block means),
#: a window's noise within 6 % and the chart's (the mean over 24 windows) within about 1.5 %:
#: below the 3.5 % of the :data:`DRAWS` Monte Carlo draws themselves (``1 / sqrt(2 DRAWS)``).
#: A larger window's statistics come from a regular lattice of its whole blocks, its mean from
#: every pixel.
SPREAD_SAMPLE_PIXELS = 128 * BLOCK_PX * BLOCK_PX
#: Placement standard uncertainty per axis of a corner not refined by the finder (px): a
#: rectangular distribution over one pixel (1/√12).
UNREFINED_PLACEMENT_PX = 1.0 / math.sqrt(12.0)

#: A function from patch means ``(..., n, 3)`` to the chart ΔE ``(...,)``.
ChartFunction = Callable[[F64], F64]


@record
class UncertaintyComponent:
    """One line of a budget: the ``name`` of the source, its standard uncertainty ``value``
    (ΔE00, k = 1), the GUM ``type`` (``A``: statistics of the data; ``B``: other knowledge)
    and ``method``, how it was obtained (in words)."""

    name: str
    value: float
    type: str
    method: str

    def to_json(self) -> dict[str, Any]:
        """``{"name", "value", "type", "method"}``."""
        return {"name": self.name, "value": self.value, "type": self.type,
                "method": self.method}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> UncertaintyComponent:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["name"]), float(d["value"]), str(d["type"]), str(d["method"]))


@record
class UncertaintyBudget:
    """The uncertainty budget of a chart ΔE (module docstring): the measured ``value`` (mean
    ΔE00), its ``components``, the Monte Carlo ``draws`` and ``seed``, and ``notes`` (patches
    whose noise could not be estimated, ...). ``combined`` is the root sum of squares, ``k``
    the coverage factor it is stated with (1)."""

    value: float
    components: tuple[UncertaintyComponent, ...]
    draws: int = DRAWS
    seed: int = SEED
    notes: tuple[str, ...] = ()
    k: float = 1.0
    quantity: str = "mean ΔE00"

    @property
    def combined(self) -> float:
        """Combined standard uncertainty u (k = 1), ΔE00."""
        return float(math.sqrt(sum(c.value ** 2 for c in self.components)))

    def expanded(self, k: float = 2.0) -> float:
        """Expanded uncertainty U = k u."""
        return float(k) * self.combined

    def component(self, name: str) -> UncertaintyComponent | None:
        """The component called ``name`` (None when absent)."""
        return next((c for c in self.components if c.name == name), None)

    def text(self) -> str:
        """``"mean ΔE00 2.41 ± 0.06 (k=1)"``: the uncertainty to two significant digits when
        it is below 0.1 (at least two decimals), the value to the same decimals."""
        return f"{self.quantity} {self.value_text()}"

    def value_text(self) -> str:
        """``"2.41 ± 0.06 (k=1)"``: :meth:`text` without the quantity's name."""
        return f"{uncertain_text(self.value, self.combined)} (k={self.k:g})"

    def to_json(self) -> dict[str, Any]:
        """``value``, ``standard_uncertainty``, ``k``, ``components``, ``method`` (the Monte
        Carlo settings), ``notes`` and the ``text``."""
        return {"quantity": self.quantity, "value": self.value,
                "standard_uncertainty": self.combined, "k": self.k,
                "components": [c.to_json() for c in self.components],
                "method": {"propagation": "Monte Carlo (JCGM 101:2008)", "draws": self.draws,
                           "placement_draws": PLACEMENT_DRAWS, "seed": self.seed,
                           "combination": "root sum of squares, components uncorrelated"},
                "notes": list(self.notes), "text": self.text()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> UncertaintyBudget:
        """Inverse of :meth:`to_json`."""
        method = d.get("method") or {}
        return cls(float(d["value"]),
                   tuple(UncertaintyComponent.from_json(c) for c in d["components"]),
                   int(method.get("draws", DRAWS)), int(method.get("seed", SEED)),
                   tuple(str(n) for n in d.get("notes") or ()), float(d.get("k", 1.0)),
                   str(d.get("quantity", "mean ΔE00")))


def uncertain_text(value: float, u: float) -> str:
    """``"2.41 ± 0.06"``: ``u`` to two significant digits (JCGM 100 7.2.6) with at least two and
    at most four decimals, ``value`` to the same decimals."""
    decimals = 2
    if u > 0 and math.isfinite(u):
        decimals = min(4, max(2, 1 - math.floor(math.log10(u))))
    return f"{value:.{decimals}f} ± {u:.{decimals}f}"


# ------------------------------------------------------------------------ the chart function


def srgb_chart_function(reference_lab: F64) -> ChartFunction:
    """``f``: encoded sRGB patch means ``(..., n, 3)`` -> mean ΔE00 against ``reference_lab``
    (a render's measurement: no exposure step, no clipping)."""
    ref = np.asarray(reference_lab, np.float64)

    def f(srgb: F64) -> F64:
        out: F64 = cm.delta_e_2000(cm.srgb_to_lab(srgb), ref).mean(axis=-1)
        return out

    return f


def exposure_of_means(linear: F64, reference_lab: F64, neutral: Sequence[int]) -> F64:
    """The auto exposure (EV) of linear sRGB patch means ``(..., n, 3)``, vectorised
    (:func:`fidelity.measure.pixels.exposure_from_neutrals` over the leading axes; a draw without
    light on any neutral patch gets EV 0)."""
    idx = np.asarray(list(neutral), dtype=int)
    y = np.asarray(linear, np.float64)[..., idx, :] @ cm.MATRIX_LINEAR_SRGB_TO_XYZ[1]
    y_ref = cm.lab_to_xyz(np.asarray(reference_lab, np.float64)[idx])[:, 1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        logs = np.log2(y_ref / y)
    ok = np.isfinite(logs) & (y > 0)
    n = ok.sum(axis=-1)
    ev: F64 = np.where(n > 0, np.where(ok, logs, 0.0).sum(axis=-1) / np.maximum(n, 1), 0.0)
    return ev


def linear_chart_function(reference_lab: F64, neutral: Sequence[int],
                          exposure_ev: float | None,
                          used: NDArray[np.bool_] | None = None) -> ChartFunction:
    """``f``: linear sRGB patch means ``(..., n, 3)`` -> mean ΔE00, as an image audit measures
    them: the exposure (``None``: auto, refitted on the ``neutral`` patches; else fixed EV),
    sRGB encoding, clipping to [0, 1], CIEDE2000 against ``reference_lab``, the mean over the
    ``used`` patches (``(n,)``; default all)."""
    ref = np.asarray(reference_lab, np.float64)
    keep = None if used is None or bool(np.all(used)) else np.asarray(used, dtype=bool)

    def f(linear: F64) -> F64:
        ev = (exposure_of_means(linear, ref, neutral) if exposure_ev is None
              else np.full(linear.shape[:-2], float(exposure_ev)))
        with np.errstate(over="ignore", invalid="ignore"):
            exposed = linear * np.exp2(ev)[..., None, None]
        srgb = np.clip(np.nan_to_num(cm.delinearize_srgb(exposed), nan=0.0, posinf=1.0,
                                     neginf=0.0), 0.0, 1.0)
        de = cm.delta_e_2000(cm.srgb_to_lab(srgb), ref)
        out: F64 = (de if keep is None else de[..., keep]).mean(axis=-1)
        return out

    return f


def _spread(values: F64) -> float:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return float(np.std(v, ddof=1)) if v.size > 1 else 0.0


# ------------------------------------------------------------------------ the components


def mean_covariance(pixels: F64, trim: float = 0.0) -> F64:
    """Covariance ``(3, 3)`` of the mean of ``(n, 3)`` pixels: ``cov / n`` (``trim`` 0), or the
    winsorised covariance over ``(1 - 2 trim)^2 n`` for a ``trim``-trimmed mean
    (Tukey & McLaughlin 1963; Wilcox, *Introduction to Robust Estimation*, 3.6). Needs
    ``n >= 2``."""
    x = np.asarray(pixels, np.float64)
    n = x.shape[0]
    if trim > 0:
        g = int(trim * n)
        if g:
            s = np.sort(x, axis=0)
            x = np.clip(x, s[g], s[n - g - 1])
    cov: F64 = np.atleast_2d(np.cov(x, rowvar=False, ddof=1)) / n
    return cov / (1.0 - 2.0 * trim) ** 2 if trim > 0 else cov


@record
class PatchSpread:
    """What the noise and rounding components need of one patch window's valid pixels,
    without the pixels (so that an audit never holds every window at once).

    ``count`` pixels; ``covariance`` ``(3, 3)``: their sample covariance (ddof 1) in the fit's
    linear domain, zero for fewer than two pixels; ``flat`` ``(3,)``: channels whose pixels are
    all equal to within round-off (:func:`flat_channels`: no noise); ``code_mean`` / ``code_std`` ``(3,)``: mean and standard
    deviation of the integer codes' values (``code / (2**bits - 1)``), None for float pixels;
    ``design`` ``(3,)``: per channel, the factor by which correlation between neighbouring
    pixels raises the variance of the mean over ``covariance / count``
    (:func:`block_design_effect`; ones when not estimated); ``sampled``: the pixels these
    statistics were computed from when fewer than ``count`` (a lattice of whole blocks,
    :func:`block_sample`), None when from all of them; ``clustered`` ``(3, 3)``: the
    covariance of the mean from the block means (:func:`block_mean_covariance`) times the
    pixels it was computed from, so that over ``count`` it is the window mean's covariance
    with the channels' correlation of the block means (JPEG's chroma noise is smoothed away
    at the pixel scale, where the channels correlate by about 0.85, but not in the block
    means, where they barely correlate), None when not estimated.
    """

    count: int
    covariance: F64
    flat: NDArray[np.bool_]
    code_mean: F64 | None = None
    code_std: F64 | None = None
    design: F64 | None = None
    sampled: int | None = None
    clustered: F64 | None = None


#: A channel whose pixels spread by no more than this many units in the last place of its
#: largest magnitude is flat: equal codes decoded by vectorised float arithmetic can differ
#: by round-off (numpy's SIMD loops and their scalar tails round differently).
ROUNDOFF_ULPS = 64


def flat_channels(values: F64) -> NDArray[np.bool_]:
    """Per channel of ``values`` ``(n, 3)``, whether its pixels are all equal to within
    :data:`ROUNDOFF_ULPS` units in the last place of its largest magnitude (exactly no noise:
    round-off is not a spread); all True for no pixels."""
    x = np.asarray(values, np.float64).reshape(-1, 3)
    if not x.shape[0]:
        return np.ones(3, bool)
    rows = np.ascontiguousarray(x.T)  # a channel's values in a row: reductions along it are fast
    return _flat(rows.max(axis=1), rows.min(axis=1))


def _flat(top: F64, bottom: F64) -> NDArray[np.bool_]:
    """:func:`flat_channels` from each channel's largest and smallest value: its spread
    (``np.ptp``) against its largest magnitude (the larger of theirs)."""
    out: NDArray[np.bool_] = ((top - bottom) <= ROUNDOFF_ULPS * np.finfo(np.float64).eps
                              * np.maximum(np.abs(top), np.abs(bottom)))
    return out


@record
class _Columns:
    """The column statistics of ``(n, k)`` float64 values (``n`` >= 1) that a window's spread
    needs, each bit for bit what numpy's own reductions over the rows give: ``mean``
    (``x.mean(axis=0)``), ``squares`` (the sums of squared deviations that ``x.var(axis=0)``
    divides), ``top`` and ``bottom`` (``x.max(axis=0)``, ``x.min(axis=0)``), ``rows`` (the
    values transposed, ``(k, n)`` contiguous) and ``deviations`` (``rows`` less their means);
    the ``linear`` columns are the pixels', the ``codes`` ones (if any) their code values'.
    numpy sums over axis 0 a row at a time in order, each row's ``k`` columns side by side:
    the same sums for all the columns at once (a window's linear values beside its codes)
    cost about what those of three do, whose per-row loop overhead dominates; the
    element-wise steps and the extremes (exact in any order) run along the transposed rows."""

    n: int
    mean: F64
    squares: F64
    top: F64
    bottom: F64
    rows: F64
    deviations: F64
    linear: tuple[int, int, int] = (0, 1, 2)
    codes: tuple[int, int, int] | None = None

    @classmethod
    def of(cls, values: F64, linear: tuple[int, int, int] = (0, 1, 2),
           codes: tuple[int, int, int] | None = None) -> _Columns:
        """The statistics of ``values`` ``(n, k)``, ``n`` >= 1."""
        x = np.ascontiguousarray(values, np.float64)
        n = x.shape[0]
        mean: F64 = x.sum(axis=0) / n
        rows = np.ascontiguousarray(x.T)
        deviations = rows - mean[:, None]
        squared = np.ascontiguousarray((deviations * deviations).T)
        return cls(n, mean, squared.sum(axis=0), rows.max(axis=1), rows.min(axis=1), rows,
                   deviations, linear, codes)

    def variance(self, ddof: int = 0) -> F64:
        """``x.var(axis=0, ddof=ddof)``."""
        out: F64 = self.squares / max(self.n - ddof, 0)
        return out

    def covariance(self) -> F64:
        """``np.cov`` of the linear columns (``rowvar=False, ddof=1``; ``n`` >= 2): their
        deviations laid out as numpy's ``cov`` lays them out for its ``dot``."""
        centred = np.ascontiguousarray(self.deviations[list(self.linear)].T)
        across = centred.T
        c: F64 = np.dot(across, across.T.conj())
        c *= np.true_divide(1, self.n - 1)
        return np.atleast_2d(c.squeeze())


def _block_deviations(values: F64, blocks: NDArray[np.int64], min_blocks: int,
                      columns: _Columns | None = None) -> tuple[F64, int, F64] | None:
    """The weighted deviations ``(n_b / n) (m_b - m)`` ``(B, 3)`` of the block means of
    ``values`` ``(n, 3)`` from their mean, the number of blocks ``B`` and the
    independent-pixel variance of the mean ``var / n`` ``(3,)``; None for fewer than 2 values
    or ``min_blocks`` blocks. ``columns``: the values' :class:`_Columns` (their linear
    columns the values), when computed already (``values`` is then not read)."""
    n = columns.n if columns is not None else np.asarray(values).reshape(-1, 3).shape[0]
    b = np.asarray(blocks, np.int64).reshape(-1)
    if n < 2 or b.size != n:
        return None
    b = b - b.min()  # a window's blocks span a few rows of the image's: a short count
    every = np.bincount(b)
    touched = every > 0
    count = int(np.count_nonzero(touched))
    if count < min_blocks:
        return None
    cols = (columns if columns is not None
            else _Columns.of(np.asarray(values, np.float64).reshape(-1, 3)))
    linear = list(cols.linear)
    sizes = every[touched]
    sums = np.stack([np.bincount(b, weights=cols.rows[c], minlength=every.size)[touched]
                     for c in linear], axis=-1)
    dev: F64 = (sizes / n)[:, None] * (sums / sizes[:, None] - cols.mean[linear])
    plain: F64 = cols.variance(ddof=1)[linear] / n
    return dev, count, plain


def block_design_effect(values: F64, blocks: NDArray[np.int64],
                        min_blocks: int = MIN_BLOCKS) -> F64 | None:
    """Per channel, how much correlation between neighbouring pixels raises the variance of
    the mean of ``values`` ``(n, 3)`` over the independent-pixel ``var / n``: the design effect
    of cluster sampling (Kish, *Survey Sampling*, 1965, 5.4), the image's
    :data:`BLOCK_PX`-square blocks (``blocks`` ``(n,)``: each pixel's block) taken as the
    clusters. The mean's variance from the block means ``m_b`` of ``n_b`` pixels, ``B`` blocks
    (the ultimate-cluster estimator of a ratio mean, Kish 6.3)::

        v = B / (B - 1) * sum_b (n_b / n)^2 (m_b - m)^2

    and the design effect ``max(1, v / (var / n))``: never below the independent-pixel
    value; 1 for a channel without variance. None for a window touching fewer than
    ``min_blocks`` blocks (too few to estimate it). JPEG's block-wise quantisation (its DC terms above
    all), demosaicing, denoising and sharpening correlate neighbouring pixels; for independent
    pixels the factor is 1 on average."""
    got = _block_deviations(values, blocks, min_blocks)
    if got is None:
        return None
    dev, count, plain = got
    return _design_effect(count / (count - 1) * (dev ** 2).sum(axis=0), plain)


def _design_effect(variance: F64, plain: F64) -> F64:
    """Per channel ``max(1, variance / plain)`` of a mean's variance over its
    independent-pixel value ``plain`` ``(3,)``; 1 for a channel without variance."""
    out = np.ones(3)
    positive = plain > 0
    out[positive] = np.maximum(1.0, variance[positive] / plain[positive])
    return out


def block_mean_covariance(values: F64, blocks: NDArray[np.int64],
                          min_blocks: int = MIN_BLOCKS, *, columns: _Columns | None = None
                          ) -> F64 | None:
    """The covariance ``(3, 3)`` of the mean of ``values`` ``(n, 3)`` from the means of the
    blocks (``blocks`` ``(n,)``) as clusters: the matrix form of the ultimate-cluster
    estimator of :func:`block_design_effect` (Kish 6.3), ``B / (B - 1) sum_b (n_b / n)^2
    d_b d_b^T`` with ``d_b = m_b - m``; each channel's variance at least the
    independent-pixel ``var / n`` (its row and column scaled up to it). None for fewer than
    ``min_blocks`` blocks. ``columns``: the values' :class:`_Columns`, when computed already."""
    got = _block_deviations(values, blocks, min_blocks, columns)
    if got is None:
        return None
    dev, count, plain = got
    cov: F64 = count / (count - 1) * (dev.T @ dev)
    diag = np.diag(cov).copy()
    scale = np.ones(3)
    low = (diag > 0) & (diag < plain)
    scale[low] = np.sqrt(plain[low] / diag[low])
    out: F64 = cov * scale[:, None] * scale[None, :]
    return out


def image_blocks(rows: NDArray[np.int64], cols: NDArray[np.int64], width: int
                 ) -> NDArray[np.int64]:
    """Each pixel's :data:`BLOCK_PX`-square block of the image (blocks counted from the
    image's top-left corner, as a JPEG's minimum coded units are), for
    :func:`block_design_effect`."""
    across = -(-int(width) // BLOCK_PX)
    out: NDArray[np.int64] = (np.asarray(rows) // BLOCK_PX) * across + \
        np.asarray(cols) // BLOCK_PX
    return out


def block_sample(y0: int, x0: int, mask: NDArray[np.bool_],
                 limit: int | None = None) -> NDArray[np.bool_] | None:
    """Which of a window's pixels (``mask`` ``(h, w)`` over the box from row ``y0``, column
    ``x0``; row-major, as :meth:`fidelity.chart.locate.PatchWindow.values` lists them) its
    statistics are computed from when it has more than ``limit``: those of every ``s``-th
    image block (:func:`image_blocks`) down and across (block indices multiples of ``s``, the
    least ``s`` that leaves at most about ``limit`` pixels), whole blocks, so that their means
    still show the correlation of neighbours (:func:`block_design_effect`) and the lattice
    spans the window. None: every pixel (``limit`` or fewer; None:
    :data:`SPREAD_SAMPLE_PIXELS`, read when called)."""
    lattice = block_lattice(y0, x0, mask, limit)
    if lattice is None:
        return None
    down, across = lattice
    keep: NDArray[np.bool_] = (mask & down[:, None] & across[None, :])[mask]
    return keep


def block_lattice(y0: int, x0: int, mask: NDArray[np.bool_], limit: int | None = None
                  ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]] | None:
    """The rows ``(h,)`` and columns ``(w,)`` of a window's box whose pixels
    :func:`block_sample` keeps (those of the window at both), or None where it keeps every
    pixel."""
    limit = SPREAD_SAMPLE_PIXELS if limit is None else int(limit)
    count = int(np.count_nonzero(mask))
    if count <= limit:
        return None
    stride = math.ceil(math.sqrt(count / limit))
    h, w = mask.shape
    down = ((np.arange(h) + y0) // BLOCK_PX) % stride == 0
    across = ((np.arange(w) + x0) // BLOCK_PX) % stride == 0
    return down, across


def patch_spread(linear: F64, codes: F64 | None = None,
                 blocks: NDArray[np.int64] | None = None,
                 count: int | None = None) -> PatchSpread:
    """The :class:`PatchSpread` of one window: ``linear`` ``(n, 3)`` valid pixels in the fit's
    domain, ``codes`` ``(n, 3)`` the same pixels' code values (integer images only),
    ``blocks`` ``(n,)`` each pixel's image block (:func:`image_blocks`), for the design effect
    of correlated neighbours (:func:`block_design_effect`; none without). ``count``: the
    window's valid pixels when these are a sample of them (:func:`block_sample`): the
    statistics are the sample's, the count (the mean's) the window's."""
    x = np.asarray(linear, np.float64).reshape(-1, 3)
    n = x.shape[0]
    c = None if codes is None else np.asarray(codes, np.float64).reshape(-1, 3)
    # one pass of column statistics over the pixels beside their codes (bit for bit numpy's
    # cov, var, mean, std, ptp and max of each)
    both = c is not None and len(c) == n
    cols = None
    if n:
        cols = (_Columns.of(np.concatenate([x, c], axis=1), codes=(3, 4, 5))
                if both and c is not None else _Columns.of(x))
    return _window_statistics(cols, n, c, blocks, count)


def coded_patch_spread(codes: NDArray[Any], table: F64,
                       blocks: NDArray[np.int64] | None = None,
                       count: int | None = None) -> PatchSpread:
    """:func:`patch_spread` of integer pixel codes ``(n, 3)`` with ``table`` ``(levels, 2)``
    each code's linear value and its code value: ``patch_spread(table[codes, 0],
    table[codes, 1], blocks, count)``, bit for bit, the pixels beside their codes gathered
    from the table at once."""
    k = np.asarray(codes).reshape(-1, 3)
    n = k.shape[0]
    if not n:
        return patch_spread(np.zeros((0, 3)), np.zeros((0, 3)), blocks, count)
    # R, its code, G, its code, B, its code: whole rows of the table at a time
    both = np.asarray(table, np.float64).take(k, axis=0).reshape(n, 6)
    return _window_statistics(_Columns.of(both, linear=(0, 2, 4), codes=(1, 3, 5)), n, both,
                              blocks, count)


def _window_statistics(cols: _Columns | None, n: int, codes: F64 | None,
                       blocks: NDArray[np.int64] | None, count: int | None) -> PatchSpread:
    """:func:`patch_spread` from the :class:`_Columns` of ``n`` pixels (their codes' too
    when ``cols.codes``; None for no pixels); ``codes`` the code values when given (read
    only where ``cols`` has none of them)."""
    total = n if count is None else int(count)
    sampled = n if total != n else None
    linear = list(cols.linear) if cols is not None else []
    cov = cols.covariance() if cols is not None and n >= 2 else np.zeros((3, 3))
    flat = (_flat(cols.top[linear], cols.bottom[linear]) if cols is not None
            else np.ones(3, bool))
    mc = (block_mean_covariance(np.zeros((0, 3)), blocks, columns=cols)
          if blocks is not None and len(blocks) == n and cols is not None
          else None)  # None: not estimated (no blocks given, or too few touched)
    # the design effect from the same block means (block_design_effect's value: the
    # covariance's diagonal is the clustered variance, raised to at least var / n)
    design = None if mc is None else _design_effect(np.diag(mc), np.diag(cov) / n)
    if design is not None:
        design[flat] = 1.0  # a flat channel's round-off spread is not noise to scale
    clustered = None if mc is None else mc * n
    if codes is None:
        return PatchSpread(total, cov, flat, design=design, sampled=sampled,
                           clustered=clustered)
    if not len(codes):
        return PatchSpread(total, cov, flat, np.zeros(3), np.zeros(3), design, sampled,
                           clustered)
    if cols is not None and cols.codes is not None:
        code_mean = cols.mean[list(cols.codes)]
        code_std = np.sqrt(cols.variance()[list(cols.codes)])
    else:
        c = np.asarray(codes, np.float64).reshape(-1, 3)
        code_mean, code_std = c.mean(axis=0), c.std(axis=0)
    return PatchSpread(total, cov, flat, code_mean, code_std, design, sampled, clustered)


def patch_covariances(samples: Sequence[F64], *, trim: float = 0.0,
                      patch_names: Sequence[str] | None = None) -> tuple[F64, tuple[str, ...]]:
    """The covariance ``(n, 3, 3)`` of each patch mean from its window's ``samples``
    ``(n_k, 3)`` (:func:`mean_covariance`; a channel of identical pixels has none), and the
    notes on patches with fewer than :data:`MIN_NOISE_PIXELS` pixels (see
    :func:`spread_covariances`)."""
    if trim == 0:
        return spread_covariances([patch_spread(s) for s in samples], patch_names=patch_names)
    per_pixel = []
    for s in samples:
        s = np.asarray(s, np.float64)
        if s.shape[0] < MIN_NOISE_PIXELS:
            per_pixel.append(PatchSpread(s.shape[0], np.zeros((3, 3)), np.ones(3, bool)))
            continue
        flat = flat_channels(s)
        per_pixel.append(PatchSpread(s.shape[0], mean_covariance(s, trim) * s.shape[0], flat))
    return spread_covariances(per_pixel, patch_names=patch_names)


def spread_covariances(spreads: Sequence[PatchSpread], *,
                       patch_names: Sequence[str] | None = None
                       ) -> tuple[F64, tuple[str, ...]]:
    """The covariance ``(n, 3, 3)`` of each patch mean, ``covariance / count`` of its
    :class:`PatchSpread` (a flat channel has none), and the notes on patches with fewer than
    :data:`MIN_NOISE_PIXELS` pixels, whose covariance is taken as the largest per-pixel
    covariance of the other patches over their own count (none such: a rectangular
    distribution over [0, 1] per channel)."""
    n = len(spreads)
    names = list(patch_names) if patch_names is not None else [f"patch {k + 1}" for k in range(n)]
    covs = np.zeros((n, 3, 3))
    per_pixel = np.zeros((n, 3, 3))
    small: list[int] = []
    for k, sp in enumerate(spreads):
        if sp.count < MIN_NOISE_PIXELS:
            small.append(k)
            continue
        per_pixel[k] = sp.covariance
        per_pixel[k][sp.flat, :] = 0.0
        per_pixel[k][:, sp.flat] = 0.0
        covs[k] = per_pixel[k] / sp.count
        if sp.clustered is not None:  # the block means' covariance, channels' correlation kept
            covs[k] = np.asarray(sp.clustered, np.float64) / sp.count
            covs[k][sp.flat, :] = 0.0
            covs[k][:, sp.flat] = 0.0
        elif sp.design is not None:  # each channel's variance raised by its design effect
            root = np.sqrt(sp.design)
            covs[k] = covs[k] * root[:, None] * root[None, :]
    notes: list[str] = []
    if small:
        others = [k for k in range(n) if k not in small]
        if others:
            worst = max(others, key=lambda j: float(np.trace(per_pixel[j])))
            for k in small:
                covs[k] = per_pixel[worst] / max(spreads[k].count, 1)
            how = f"the largest per-pixel noise of the other patches ({names[worst]})"
        else:
            for k in small:
                covs[k] = np.eye(3) / 12.0 / max(spreads[k].count, 1)
            how = "a rectangular distribution over [0, 1] per channel"
        notes.append("pixel noise not estimable from fewer than "
                     f"{MIN_NOISE_PIXELS} valid pixels in " + ", ".join(names[k] for k in small)
                     + f"; taken as {how}")
    return covs, tuple(notes)


def noise_component(samples: Sequence[F64], means: F64, f: ChartFunction, *,
                    trim: float = 0.0, patch_names: Sequence[str] | None = None,
                    rng: np.random.Generator | None = None, draws: int = DRAWS,
                    covariances: F64 | None = None, designs: Sequence[F64 | None] = (),
                    sampled: Sequence[int | None] = (),
                    ) -> tuple[UncertaintyComponent, tuple[str, ...]]:
    """The ``pixel noise`` component of ``f`` at ``means`` ``(n, 3)`` from each patch's
    ``samples`` ``(n_k, 3)`` (module docstring; ``covariances``: those of
    :func:`patch_covariances` or :func:`spread_covariances`, computed here when None;
    ``designs``: the windows' design effects those covariances carry, ``sampled``: the pixels of
    each window they were computed from when a sample (:func:`block_sample`), both for the
    method's words), and the notes on patches too small to estimate their own noise."""
    rng = rng if rng is not None else np.random.default_rng(SEED)
    notes: tuple[str, ...] = ()
    if covariances is None:
        covariances, notes = patch_covariances(samples, trim=trim, patch_names=patch_names)
    covs = np.asarray(covariances, np.float64)
    n = covs.shape[0]
    # a square root of each covariance by its eigen-decomposition (singular ones, e.g. grey
    # pixels or perfectly correlated channels, included; round-off negatives set to 0)
    vals, vecs = np.linalg.eigh(covs)
    chol = vecs * np.sqrt(np.maximum(vals, 0.0))[:, None, :]
    z = rng.standard_normal((draws, n, 3))
    drawn = np.asarray(means, np.float64)[None] + np.einsum("kij,bkj->bki", chol, z)
    value = 0.0 if not np.any(covs) else _spread(f(drawn))
    how = ("sample covariance of each patch window's pixels / n" if trim == 0 else
           f"winsorised covariance of each patch window's pixels / ((1 - 2*{trim:g})^2 n) "
           f"({trim:g}-trimmed mean)")
    estimated = [d for d in designs if d is not None]
    if estimated:
        top = max(float(np.max(d)) for d in estimated)
        how += (f", the covariance of each window's mean from its {BLOCK_PX} x {BLOCK_PX}-pixel "
                f"blocks' means as clusters where neighbouring pixels are alike (Kish's "
                f"ultimate-cluster estimator, the channels' correlation kept, each channel's "
                f"variance at least var / n; {len(estimated)} of {len(designs)} windows over "
                f"{MIN_BLOCKS} blocks or more, largest design effect {top:.3g})")
    subsets = [s for s in sampled if s is not None]
    if subsets:
        how += (f"; in the {len(subsets)} windows over {SPREAD_SAMPLE_PIXELS} pixels the "
                f"per-pixel covariance and design effect from a lattice of whole "
                f"{BLOCK_PX} x {BLOCK_PX}-pixel blocks ({min(subsets)} to {max(subsets)} "
                f"pixels), divided by the window's own count")
    return (UncertaintyComponent(
        "pixel noise", value, "A",
        f"{how}; patch means drawn from the normal distribution with it, {draws} Monte Carlo "
        f"draws propagated through the chart ΔE (the exposure refitted on each draw when "
        f"auto)"), notes)


#: Terms of the Fourier series of :func:`rounding_residual` (the tail beyond is below 0.3 %
#: of the undithered value).
ROUNDING_TERMS = 256


def rounding_residual(code_std: ArrayLike, step: float) -> F64:
    """Standard uncertainty of the rounding error left in the mean of integer codes whose
    values spread by ``code_std`` (any shape, same unit as ``step``): codes that vary dither
    their own rounding. The spread before rounding ``s`` from Sheppard's correction for
    grouping (``s² = max(0, code_std² - step²/12)``); for values spread normally by ``s``, the
    mean of the codes departs from the values' mean by the rounding sawtooth's Fourier series,
    each term ``k`` damped by ``exp(-2 π² k² s² / step²)`` (Widrow & Kollár, *Quantization
    Noise*, 2008, ch. 4-5); its RMS over the unknown place of the value within a step::

        u = step * sqrt(sum_k exp(-4 π² k² s² / step²) / (2 π² k²))

    ``step / √12`` for codes that do not vary (the rectangular distribution over ±step/2,
    JCGM 100 F.2.2.1), 0.8 % of a step at a spread of half a step, vanishing beyond."""
    sd = np.asarray(code_std, np.float64)
    s2 = np.maximum(sd * sd - step * step / 12.0, 0.0) / (step * step)
    k = np.arange(1, ROUNDING_TERMS + 1, dtype=np.float64)
    terms = np.exp(-4.0 * np.pi ** 2 * s2[..., None] * k ** 2) / (2.0 * np.pi ** 2 * k ** 2)
    tail = 1.0 / 12.0 - float(np.sum(1.0 / (2.0 * np.pi ** 2 * k ** 2)))  # undithered rest
    total = terms.sum(axis=-1) + np.where(s2 == 0.0, tail, 0.0)
    out: F64 = step * np.sqrt(total)
    return out


def rounding_component(samples: Sequence[F64], means: F64, f: ChartFunction, step: float | None,
                       *, encoded: Sequence[F64] | None = None,
                       to_measured: Callable[[F64], F64] | None = None,
                       code_std: F64 | None = None,
                       rng: np.random.Generator | None = None, draws: int = DRAWS,
                       ) -> UncertaintyComponent:
    """The ``rounding`` component: each patch channel's mean of integer codes of ``step``
    carries the rounding error its codes' spread leaves (:func:`rounding_residual`:
    ``step/√12`` when the codes do not vary, none once they vary by half a step), drawn
    rectangular with that standard deviation. ``encoded``: the pixels in the coded domain
    (default ``samples``); ``to_measured`` maps a code-domain error of the patch means to the
    domain of ``means`` (a derivative; default identity); ``code_std`` ``(n, 3)``: the codes'
    standard deviations when known without the pixels (:attr:`PatchSpread.code_std`).
    ``step`` None: no integer codes (float pixels), zero."""
    if not step:
        return UncertaintyComponent("rounding", 0.0, "B",
                                    "floating-point pixels: no rounding to integer codes")
    rng = rng if rng is not None else np.random.default_rng(SEED + 1)
    if code_std is None:
        codes = encoded if encoded is not None else samples
        code_std = np.array([np.asarray(c, np.float64).std(axis=0) if len(c) else np.zeros(3)
                             for c in codes])
    residual = rounding_residual(code_std, step)
    e = rng.uniform(-0.5, 0.5, (draws, *residual.shape)) * (math.sqrt(12.0) * residual)[None]
    if to_measured is not None:
        e = to_measured(e)
    full = step / math.sqrt(12.0)
    value = _spread(f(np.asarray(means, np.float64)[None] + e)) if residual.any() else 0.0
    return UncertaintyComponent(
        "rounding", value, "B",
        f"pixel codes of step {step:.3g}: each patch channel's mean carries the rounding its "
        f"codes' spread leaves (Sheppard-corrected spread, the dithered rounding error's "
        f"Fourier series: step/√12 for codes that do not vary, none beyond half a step; "
        f"{int(np.sum(residual > 0.5 * full))} of {residual.size} channels above half of "
        f"step/√12), rectangular, {draws} Monte Carlo draws")


#: The chromatic adaptation transforms whose spread is the ``chromatic adaptation`` component
#: (:func:`adaptation_component`): the von Kries-type cone-space transforms a colour scientist
#: would choose between (XYZ Scaling, not a cone space, is left out of the spread).
ADAPTATION_SPREAD = ("Bradford", "CAT02", "CAT16", "Von Kries")


def adaptation_component(mean_delta_e_by_cat: Mapping[str, float], chosen: str
                         ) -> UncertaintyComponent:
    """The ``chromatic adaptation`` component (type B) of a chart ΔE against a scene
    reference adapted from a non-D65 illuminant to D65: which transform adapts the reference
    is a method choice, not a measurement, and it moves the ΔE (under illuminant A, von Kries
    2.56 against CAT02 3.53 for one camera, issue 58).

    Parameters
    ----------
    mean_delta_e_by_cat
        The chart's mean ΔE00 against the reference adapted by each transform of
        :data:`ADAPTATION_SPREAD` (the same measured colours; ΔE00).
    chosen
        The transform the reported ΔE used (``--cat``).

    Returns
    -------
    UncertaintyComponent
        Value ``(max - min) / (2 sqrt 3)`` ΔE00: half the range of the transforms' mean ΔE00
        taken as the half-width of a rectangular distribution (GUM 4.3.7: every transform
        in the range equally plausible, none outside it); the method names each
        transform's ΔE.
    """
    values = [float(v) for v in mean_delta_e_by_cat.values()]
    half = (max(values) - min(values)) / 2.0 if values else 0.0
    each = ", ".join(f"{k} {v:.2f}" for k, v in mean_delta_e_by_cat.items())
    return UncertaintyComponent(
        "chromatic adaptation", half / math.sqrt(3.0), "B",
        f"the reference's adaptation to D65 is a method choice ({chosen} used): mean ΔE00 "
        f"{each}; half their range as a rectangular half-width, / √3")


def exposure_component(linear_means: F64, reference_lab: F64, neutral: Sequence[int],
                       exposure_ev: float, f_ev0: ChartFunction, covariances: F64, *,
                       rng: np.random.Generator | None = None, draws: int = DRAWS,
                       ) -> UncertaintyComponent:
    """The ``exposure normalisation`` component of an auto exposure: how much the neutral
    patches disagree about the exposure beyond what their pixel noise explains (that part is
    in the pixel noise component, which refits the exposure on every draw).

    ``EV`` is the mean of ``k`` log2 luminance ratios ``r_i``; its standard uncertainty
    ``sqrt(max(0, s^2 - mean_i u_i^2) / k)`` with ``s`` the standard deviation of the ``r_i``
    and ``u_i`` the pixel-noise standard uncertainty of ``r_i`` (from the patch mean's
    ``covariances``), propagated through the chart function with a fixed exposure
    (``f_ev0``: EV 0, the means scaled)."""
    rng = rng if rng is not None else np.random.default_rng(SEED + 2)
    idx = np.asarray(list(neutral), dtype=int)
    w = cm.MATRIX_LINEAR_SRGB_TO_XYZ[1]
    y = np.asarray(linear_means, np.float64)[idx] @ w
    y_ref = cm.lab_to_xyz(np.asarray(reference_lab, np.float64)[idx])[:, 1]
    u_y = np.sqrt(np.maximum(np.einsum("i,kij,j->k", w, np.asarray(covariances)[idx], w), 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        logs = np.log2(y_ref / y)
        u_logs = u_y / (y * math.log(2.0))
    ok = np.isfinite(logs) & np.isfinite(u_logs) & (y > 0)
    if ok.sum() < 2:
        return UncertaintyComponent("exposure normalisation", 0.0, "A",
                                    "fewer than 2 neutral patches with light: not estimable")
    logs, u_logs = logs[ok], u_logs[ok]
    excess = max(0.0, float(np.var(logs, ddof=1) - np.mean(u_logs ** 2)))
    u_ev = math.sqrt(excess / logs.size)
    evs = exposure_ev + u_ev * rng.standard_normal(draws)
    scaled = np.asarray(linear_means, np.float64)[None] * np.exp2(evs)[:, None, None]
    value = _spread(f_ev0(scaled)) if u_ev > 0 else 0.0
    return UncertaintyComponent(
        "exposure normalisation", value, "A",
        f"disagreement of the {logs.size} neutral patches about the auto exposure beyond their "
        f"pixel noise, sqrt(max(0, s^2 - mean u_i^2) / k) of their log2 luminance ratios = "
        f"{u_ev:.4f} EV, {draws} Monte Carlo draws")


def placement_component(remeasure: Callable[[F64], F64 | None], corners: F64,
                        sigma_px: float, how: str, f: ChartFunction, *,
                        rng: np.random.Generator | None = None,
                        draws: int = PLACEMENT_DRAWS) -> UncertaintyComponent:
    """The ``placement`` component: the patch means measured again (``remeasure``: corners
    ``(4, 2)`` -> patch means ``(n, 3)``, None when the jittered corners cannot be measured)
    with the corners jittered by ``sigma_px`` per axis (normal), ``draws`` times, and the
    chart ΔE ``f`` of each; ``how`` says where ``sigma_px`` comes from."""
    rng = rng if rng is not None else np.random.default_rng(SEED + 3)
    means = []
    for _ in range(draws):
        m = remeasure(np.asarray(corners, np.float64)
                      + sigma_px * rng.standard_normal((4, 2)))
        if m is not None:
            means.append(m)
    value = _spread(f(np.stack(means))) if len(means) > 1 else 0.0
    lost = draws - len(means)
    extra = f"; {lost} draws could not be measured" if lost else ""
    return UncertaintyComponent(
        "placement", value, "B",
        f"corners jittered by {sigma_px:.3f} px per axis ({how}), windows located again and "
        f"the chart measured again, {draws} draws{extra}")


__all__ = [
    "ADAPTATION_SPREAD",
    "DRAWS",
    "MIN_NOISE_PIXELS",
    "PLACEMENT_DRAWS",
    "SEED",
    "SPREAD_SAMPLE_PIXELS",
    "UNREFINED_PLACEMENT_PX",
    "ChartFunction",
    "PatchSpread",
    "UncertaintyBudget",
    "UncertaintyComponent",
    "adaptation_component",
    "exposure_component",
    "exposure_of_means",
    "linear_chart_function",
    "mean_covariance",
    "noise_component",
    "patch_covariances",
    "block_lattice",
    "block_mean_covariance",
    "block_sample",
    "flat_channels",
    "coded_patch_spread",
    "patch_spread",
    "placement_component",
    "rounding_component",
    "spread_covariances",
    "srgb_chart_function",
    "uncertain_text",
]
