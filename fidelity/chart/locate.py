"""Locate the 24 patches of a 4 x 6 colour chart in an image from its four corner patches.

The user gives the image positions of the centres of the four corner patches in this order:
dark skin, bluish green, black, white, i.e. the chart's top-left, top-right, bottom-right and
bottom-left patch as seen on the chart (any rotation, mirroring or perspective in the image is
allowed). In chart *grid* coordinates ``(u, v)`` the centre of the patch in column ``c``, row
``r`` is ``(c, r)``; so the corner centres are ``(0, 0), (5, 0), (5, 3), (0, 3)``, one grid unit
is the patch pitch, and a projective map (homography) ``H`` takes the grid to the image:
``(x, y, 1)^T ~ H (u, v, 1)^T`` (Hartley & Zisserman, *Multiple View Geometry*, 2nd ed.,
Alg. 4.1, DLT from four correspondences).

Image coordinates are in pixels, ``x`` along a row (column index), ``y`` down (row index),
with the centre of pixel ``(i, j)`` at ``x = j, y = i``. A patch is sampled in a central square
window of ``window`` patch pitches per side (default 0.5), taken in grid coordinates so that it
follows perspective: a pixel belongs to the window of patch ``(c, r)`` when its centre maps to
``|u - c| <= window/2`` and ``|v - r| <= window/2``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

#: Names of the corner patches, in the order the corners are given.
CORNER_PATCHES: tuple[str, str, str, str] = ("dark skin", "bluish green", "black", "white")
#: Default side of the central sampling window, in patch pitches.
DEFAULT_WINDOW = 0.5
#: Fewest pixels a sampling window may hold before the chart counts as too small to sample.
MIN_WINDOW_PIXELS = 9


def parse_corners(text: str | Sequence[float]) -> np.ndarray:
    """Parse ``"X1,Y1,X2,Y2,X3,Y3,X4,Y4"`` (or 8 numbers) into a ``(4, 2)`` float64 array."""
    if isinstance(text, str):
        items = [t for t in text.replace(";", ",").replace(" ", ",").split(",") if t.strip()]
        try:
            values = [float(t) for t in items]
        except ValueError:
            raise InvalidValueError(
                f"--corners {text!r}: expected 8 numbers X1,Y1,X2,Y2,X3,Y3,X4,Y4"
            ) from None
    else:
        values = [float(v) for v in text]
    if len(values) != 8:
        raise InvalidValueError(
            f"--corners {text!r}: expected 8 numbers X1,Y1,X2,Y2,X3,Y3,X4,Y4 "
            f"(centres of the {', '.join(CORNER_PATCHES)} patches), got {len(values)}"
        )
    arr = np.asarray(values, dtype=np.float64).reshape(4, 2)
    if not np.all(np.isfinite(arr)):
        raise InvalidValueError(f"--corners {text!r}: corners must be finite numbers")
    return arr


def homography_from_points(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The 3 x 3 homography ``H`` with ``dst ~ H src`` from four or more point pairs.

    Normalised DLT (Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., Alg. 4.2): each
    point set is moved to its centroid and scaled to mean distance sqrt(2), the DLT is solved by
    SVD, and the normalisation undone. Four pairs give the exact map; more give the algebraic
    least-squares fit. ``src`` and ``dst`` are ``(N, 2)``, ``N >= 4``; ``H`` is normalised to
    ``H[2, 2] = 1``. Raises :class:`InvalidValueError` when four points have three collinear
    ones, or more points all lie on one line (no unique map).
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 2 or len(src) < 4:
        raise InvalidValueError(f"a homography needs N >= 4 point pairs of shape (N, 2), got "
                                f"{src.shape} and {dst.shape}")
    for name, pts in (("source", src), ("corner", dst)):
        scale = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])), 1e-12)
        if len(pts) == 4:
            for skip in range(4):
                tri = np.delete(pts, skip, axis=0)
                (ax, ay), (bx, by) = tri[1] - tri[0], tri[2] - tri[0]
                area = abs(ax * by - ay * bx) / 2.0
                if area <= 1e-9 * scale * scale:
                    raise InvalidValueError(
                        f"{name} points are degenerate (three of them are collinear or "
                        f"coincide): {pts.tolist()}"
                    )
        else:
            spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
            if spread[-1] <= 1e-9 * scale:
                raise InvalidValueError(f"{name} points are degenerate (all on one line)")

    def normaliser(pts: np.ndarray) -> np.ndarray:
        centre = pts.mean(axis=0)
        mean_dist = float(np.mean(np.linalg.norm(pts - centre, axis=-1)))
        s = math.sqrt(2.0) / mean_dist
        return np.array([[s, 0, -s * centre[0]], [0, s, -s * centre[1]], [0, 0, 1.0]])

    t_src, t_dst = normaliser(src), normaliser(dst)
    a = src @ t_src[:2, :2].T + t_src[:2, 2]
    b = dst @ t_dst[:2, :2].T + t_dst[:2, 2]
    rows = []
    for (u, v), (x, y) in zip(a, b, strict=True):
        rows.append([u, v, 1, 0, 0, 0, -x * u, -x * v, -x])
        rows.append([0, 0, 0, u, v, 1, -y * u, -y * v, -y])
    _, _, vt = np.linalg.svd(np.asarray(rows), full_matrices=len(rows) < 9)
    h = np.linalg.inv(t_dst) @ vt[-1].reshape(3, 3) @ t_src
    if abs(h[2, 2]) < 1e-15:
        raise InvalidValueError("corner points give a degenerate homography")
    out: np.ndarray = h / h[2, 2]
    return out


def apply_homography(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map ``(..., 2)`` points through ``h``: ``(x, y) = (h @ (u, v, 1))[:2] / w``."""
    pts = np.asarray(points, dtype=np.float64)
    x, y = pts[..., 0], pts[..., 1]
    # element-wise, not ``pts @ h[:, :2].T``: a matmul of inner size 2 over millions of
    # points is an order of magnitude slower
    w = h[2, 0] * x + h[2, 1] * y + h[2, 2]
    out: np.ndarray = np.stack([(h[0, 0] * x + h[0, 1] * y + h[0, 2]) / w,
                                (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / w], axis=-1)
    return out


@dataclass(frozen=True, eq=False)
class PatchWindow:
    """The pixels of one patch's sampling window: those set in ``mask`` (``(h, w)`` bool) over
    the box of rows ``y0 .. y0 + h - 1`` and columns ``x0 .. x0 + w - 1``, in row-major order.

    Unpacks like the pair of row and column index arrays it stands for (``rows, cols =
    window``), at one byte per pixel of the box instead of sixteen per pixel."""

    y0: int
    x0: int
    mask: np.ndarray
    count: int

    def indices(self) -> tuple[np.ndarray, np.ndarray]:
        """Row and column indices (int64) of the window's pixels, row-major."""
        rows, cols = np.nonzero(self.mask)
        return rows.astype(np.int64) + self.y0, cols.astype(np.int64) + self.x0

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter(self.indices())

    def __getitem__(self, index: int) -> np.ndarray:
        return self.indices()[index]

    def __len__(self) -> int:
        return 2

    def values(self, pixels: np.ndarray) -> np.ndarray:
        """``(count, C)`` values of ``pixels`` (``(H, W, C)``, any dtype, not copied whole) in
        the window, row-major: ``pixels[rows, cols]``."""
        h, w = self.mask.shape
        box = np.asarray(pixels)[self.y0:self.y0 + h, self.x0:self.x0 + w]
        if self.count == h * w:  # the whole box (a chart square to the image)
            return box.reshape(h * w, *box.shape[2:]).copy()
        lengths = self.mask.sum(axis=1)
        first = self.mask.argmax(axis=1)
        last = w - 1 - self.mask[:, ::-1].argmax(axis=1)
        rows = np.flatnonzero(lengths)
        if np.array_equal(last[rows] - first[rows] + 1, lengths[rows]):  # one run per row
            return np.concatenate([box[r, first[r]:first[r] + lengths[r]] for r in rows])
        out: np.ndarray = box[self.mask]
        return out


#: Pixels either side of a window's edge, along a row, whose centres are mapped to the grid
#: to decide whether they are in it (those farther in are, those farther out are not).
EDGE_PIXELS = 2


def _inside(h_inv: np.ndarray, xs: np.ndarray, ys: np.ndarray, centre: tuple[float, float],
            half: float) -> np.ndarray:
    """Whether pixel centres ``(xs, ys)`` map within ``half`` (+1e-9) of ``centre`` in grid
    coordinates."""
    uv = apply_homography(h_inv, np.stack([xs, ys], axis=-1).astype(np.float64))
    out: np.ndarray = ((np.abs(uv[..., 0] - centre[0]) <= half + 1e-9)
                       & (np.abs(uv[..., 1] - centre[1]) <= half + 1e-9))
    return out


def _window_mask(h_inv: np.ndarray, box: tuple[int, int, int, int], centre: tuple[float, float],
                 half: float, quad: np.ndarray) -> np.ndarray:
    """Which pixels of ``box`` (x0, y0, x1, y1, inclusive) map within ``half`` of ``centre`` in
    grid coordinates: the pixels of the convex quadrilateral ``quad`` (the window's corners in
    the image). Each row crosses it in one run of pixels; the pixels within
    :data:`EDGE_PIXELS` of the run's ends are mapped to the grid to decide, the rest filled,
    so that the work grows with the window's perimeter, not its area."""
    x0, y0, x1, y1 = box
    width = x1 - x0 + 1
    ys = np.arange(y0, y1 + 1, dtype=np.float64)
    # where each row's line crosses the quadrilateral's edges
    ends = np.full((len(ys), 2), np.nan)
    for (px, py), (qx, qy) in zip(quad, np.roll(quad, -1, axis=0), strict=True):
        if py == qy:
            continue
        t = (ys - py) / (qy - py)
        x = np.where((t >= 0) & (t <= 1), px + t * (qx - px), np.nan)
        with np.errstate(invalid="ignore"):
            ends[:, 0] = np.fmin(ends[:, 0], x)
            ends[:, 1] = np.fmax(ends[:, 1], x)
    test_rows: list[np.ndarray] = []
    test_cols: list[np.ndarray] = []
    crossed = np.isfinite(ends[:, 0])
    for r in np.flatnonzero(~crossed):  # rows that miss it (by rounding): every pixel tested
        test_rows.append(np.full(width, r))
        test_cols.append(np.arange(width))
    rows = np.flatnonzero(crossed)
    lo = np.clip(np.floor(ends[rows, 0]).astype(np.int64) - x0 - EDGE_PIXELS, 0, width)
    hi = np.clip(np.ceil(ends[rows, 1]).astype(np.int64) - x0 + EDGE_PIXELS + 1, 0, width)
    keep = hi > lo
    rows, lo, hi = rows[keep], lo[keep], hi[keep]
    # the run's inside, filled: +1 where it starts, -1 where it stops, summed along the row
    k = 2 * EDGE_PIXELS + 1
    start, stop = lo + k, hi - k
    wide = stop > start
    steps = np.zeros((len(ys), width + 1), dtype=np.int8)
    steps[rows[wide], start[wide]] = 1
    steps[rows[wide], stop[wide]] = -1
    mask = np.cumsum(steps, axis=1, dtype=np.int8)[:, :width] > 0
    # the k pixels at each end of the run (all of a short run) are tested
    span = np.arange(k)
    cols = np.concatenate([lo[:, None] + span, hi[:, None] - k + span], axis=1)
    cols = np.clip(cols, lo[:, None], hi[:, None] - 1)
    test_rows.append(np.repeat(rows, 2 * k))
    test_cols.append(cols.ravel())
    if test_rows:
        rr, cc = np.concatenate(test_rows), np.concatenate(test_cols)
        mask[rr, cc] = _inside(h_inv, cc + x0, rr + y0, centre, half)
    return mask


@record
class ChartLocation:
    """Where the chart's patches lie in an image.

    ``homography`` maps grid ``(u, v)`` to image ``(x, y)``; ``centres`` is ``(24, 2)`` image
    ``(x, y)`` of the patch centres in row-major order; ``windows[k]`` holds the pixels in patch
    ``k``'s sampling window (a :class:`PatchWindow`, which unpacks as the row and column index
    arrays); ``pitch_px`` is the
    smallest distance between neighbouring patch centres in pixels.
    """

    corners: np.ndarray
    homography: np.ndarray
    centres: np.ndarray
    windows: tuple[PatchWindow, ...]
    window: float
    pitch_px: float
    rows: int
    cols: int

    def to_json(self) -> dict[str, object]:
        """JSON form: corners, homography, centres, window size and pixel counts."""
        return {
            "corners": self.corners.tolist(),
            "corner_patches": list(CORNER_PATCHES),
            "homography": self.homography.tolist(),
            "centres": np.round(self.centres, 3).tolist(),
            "window_pitch_fraction": self.window,
            "window_pixels": [int(w.count) for w in self.windows],
            "pitch_px": round(self.pitch_px, 3),
        }


def grid_centres(rows: int = 4, cols: int = 6) -> np.ndarray:
    """Grid coordinates ``(u, v) = (c, r)`` of the patch centres, row-major, ``(rows*cols, 2)``."""
    r, c = np.mgrid[0:rows, 0:cols]
    return np.stack([c.ravel(), r.ravel()], axis=-1).astype(np.float64)


def locate_chart(
    corners: np.ndarray | str | Sequence[float],
    image_shape: tuple[int, ...],
    *,
    rows: int = 4,
    cols: int = 6,
    window: float = DEFAULT_WINDOW,
    min_pixels: int = MIN_WINDOW_PIXELS,
    patch_names: Sequence[str] | None = None,
) -> ChartLocation:
    """Locate every patch of a ``rows`` x ``cols`` chart from its four corner-patch centres.

    Parameters
    ----------
    corners
        ``(4, 2)`` image ``(x, y)`` of the centres of the dark skin, bluish green, black and
        white patches (or the ``"X1,Y1,...,X4,Y4"`` string).
    image_shape
        ``(H, W, ...)`` of the image.
    rows, cols
        The chart's layout (4 x 6 for a Macbeth ColorChecker).
    window
        Side of the central sampling square in patch pitches, in (0, 1].
    min_pixels
        Fewest pixels a sampling window may hold (default :data:`MIN_WINDOW_PIXELS`).
    patch_names
        The rows*cols patch names, row-major; None: ``patch 1``, ``patch 2``, ...

    Raises
    ------
    InvalidValueError
        Corners outside the image, degenerate corners, a sampling window that leaves the image
        or crosses the horizon of the perspective, or a chart too small to sample (a window
        with fewer than ``min_pixels`` pixels).
    """
    if not 0.0 < window <= 1.0:
        raise InvalidValueError(f"sampling window {window} must be in (0, 1] patch pitches")
    pts = parse_corners(corners) if isinstance(corners, str) else np.asarray(corners, np.float64)
    if pts.shape != (4, 2):
        raise InvalidValueError(f"corners must be 4 (x, y) points, got shape {pts.shape}")
    height, width = int(image_shape[0]), int(image_shape[1])
    names = list(patch_names) if patch_names is not None else [
        f"patch {k + 1}" for k in range(rows * cols)]
    for name, (x, y) in zip(CORNER_PATCHES, pts, strict=True):
        if not (-0.5 <= x <= width - 0.5 and -0.5 <= y <= height - 0.5):
            raise InvalidValueError(
                f"corner {name!r} at ({x:g}, {y:g}) is outside the {width}x{height} image "
                f"(x in [0, {width - 1}], y in [0, {height - 1}])"
            )
    grid_corners = np.array([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]], float)
    h = homography_from_points(grid_corners, pts)
    h_inv = np.linalg.inv(h)
    grid = grid_centres(rows, cols)
    half = window / 2.0
    offsets = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    # Every window corner must lie on the same side of the horizon (w > 0 after the map).
    all_window_corners = (grid[:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    w = all_window_corners @ h[2, :2] + h[2, 2]
    if np.any(w <= 0):
        raise InvalidValueError("corners give a perspective in which the chart crosses the horizon")
    centres = apply_homography(h, grid)
    windows: list[PatchWindow] = []
    for k, (u0, v0) in enumerate(grid):
        quad = apply_homography(h, offsets + (u0, v0))
        if (quad[:, 0].min() < -0.5 or quad[:, 0].max() > width - 0.5
                or quad[:, 1].min() < -0.5 or quad[:, 1].max() > height - 0.5):
            raise InvalidValueError(
                f"patch {names[k]!r}: its sampling window (x {quad[:, 0].min():.1f} to "
                f"{quad[:, 0].max():.1f}, y {quad[:, 1].min():.1f} to {quad[:, 1].max():.1f}) "
                f"reaches outside the {width}x{height} image (check --corners: centres of "
                f"{', '.join(CORNER_PATCHES)})"
            )
        x0 = max(int(np.floor(quad[:, 0].min())), 0)
        x1 = min(int(np.ceil(quad[:, 0].max())), width - 1)
        y0 = max(int(np.floor(quad[:, 1].min())), 0)
        y1 = min(int(np.ceil(quad[:, 1].max())), height - 1)
        mask = _window_mask(h_inv, (x0, y0, x1, y1), (float(u0), float(v0)), half, quad)
        windows.append(PatchWindow(y0, x0, mask, int(np.count_nonzero(mask))))
    c2 = centres.reshape(rows, cols, 2)
    steps = np.concatenate([
        np.linalg.norm(np.diff(c2, axis=1), axis=-1).ravel(),
        np.linalg.norm(np.diff(c2, axis=0), axis=-1).ravel(),
    ])
    pitch = float(steps.min())
    counts = [wi.count for wi in windows]
    k_min = int(np.argmin(counts))
    if counts[k_min] < min_pixels:
        raise InvalidValueError(
            f"chart too small to sample: patch {names[k_min]!r} has {counts[k_min]} pixel(s) in "
            f"its central window (need at least {min_pixels}); patch pitch is about {pitch:.1f} "
            f"px, need about {np.sqrt(min_pixels) / window:.0f} px or more"
        )
    return ChartLocation(
        corners=pts, homography=h, centres=centres, windows=tuple(windows), window=window,
        pitch_px=pitch, rows=rows, cols=cols,
    )


def window_pixels(pixels: np.ndarray, location: ChartLocation) -> list[np.ndarray]:
    """The ``(n_k, C)`` pixel values inside each patch's sampling window, row-major."""
    return [w.values(pixels) for w in location.windows]


__all__ = [
    "CORNER_PATCHES",
    "DEFAULT_WINDOW",
    "MIN_WINDOW_PIXELS",
    "ChartLocation",
    "PatchWindow",
    "apply_homography",
    "grid_centres",
    "homography_from_points",
    "locate_chart",
    "parse_corners",
    "window_pixels",
]
