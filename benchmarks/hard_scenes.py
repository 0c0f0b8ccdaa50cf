"""Hard synthetic photos of a 24-patch chart: the failure kinds seen on real photos.

Built on :mod:`benchmarks.chart_scenes` (the same closed-form homography, so the true corner
patch centres are known independently of fidelity.chart). Hazards (:data:`HAZARDS`):

``distractors``
    the chart lies on a mat beside other square, patch-like objects in its own plane: a board
    of coloured tiles (3-6 x 3-6, at 0.8-1.25 times the chart's pitch) a fraction of a pitch
    from the chart's frame, a checkerboard of squares and a grey card;
``occluder``
    a leaf- or hand-like shape, filled with a texture cut from another part of the photo, over
    two neighbouring patches (their 0-based indices in ``Scene.conditions['occluded']``);
``isp``
    a camera ISP's look on the 8-bit frame: strong local tone mapping (CLAHE on the lightness
    of CIELAB, clip limit 3-5, 8 x 8 tiles) and unsharp-mask sharpening with halos (amount
    1-2.5, radius 1.5-3 px), at dashcam size (1920 x 1080 unless told).
"""

from __future__ import annotations

import math

import numpy as np

from benchmarks.chart_scenes import (
    CORNER_CELLS,
    FRAME,
    FRAME_LINEAR,
    Scene,
    _background,
    _map,
    _paint_grid,
    chart_homography,
    decode_jpeg,
)
from fidelity.colour import colorimetry as cm

#: Hazards drawn here.
HAZARDS = ("distractors", "occluder", "isp")


def _chart(patch_linear: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    w, h = round((5 + 2 * FRAME) * pitch), round((3 + 2 * FRAME) * pitch)
    tex = np.full((h + 1, w + 1, 3), FRAME_LINEAR)
    origin = (FRAME * pitch, FRAME * pitch)
    _paint_grid(tex, patch_linear, 4, 6, origin, pitch)
    return tex, np.asarray(origin + CORNER_CELLS * pitch)


def _distractor_mat(patch_linear: np.ndarray, pitch: float, rng: np.random.Generator
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The chart on a mat with a tile board beside it, a checkerboard below and a grey card:
    ``(texture, corner centres)``."""
    chart, corners = _chart(patch_linear, pitch)
    ch, cw = chart.shape[:2]
    aligned = rng.uniform() < 0.5  # tiles on the chart's own grid, as if they continued it
    t_pitch = pitch if aligned else pitch * rng.uniform(0.8, 1.25)
    t_rows, t_cols = (4, int(rng.integers(2, 5))) if aligned else \
        (int(rng.integers(3, 7)), int(rng.integers(3, 7)))
    # aligned: the first tile column's centres 1.2 pitches beyond the chart's last column
    gap = (1.2 - FRAME - 0.6) * pitch if aligned else pitch * rng.uniform(0.15, 0.8)
    board_w = round(t_cols * t_pitch + 0.2 * t_pitch)
    board_h = round(t_rows * t_pitch + 0.2 * t_pitch)
    c_pitch = pitch * rng.uniform(0.7, 1.3)
    c_n = int(rng.integers(5, 9))
    check_side = round(c_n * c_pitch)
    card = round(pitch * rng.uniform(1.5, 3.0))
    mat = rng.uniform(0.15, 0.5) * np.array([1.0, 0.95, 0.85])
    width = round(cw + abs(gap) + max(board_w, card) + 2 * pitch)
    height = round(max(ch, board_h) + abs(gap) + max(check_side, card) + 2 * pitch)
    tex = np.empty((height, width, 3))
    tex[:] = mat
    y_chart = round(pitch)
    x_chart = round(pitch)
    tex[y_chart:y_chart + ch, x_chart:x_chart + cw] = chart
    corners = corners + (x_chart, y_chart)
    # tiles: random colours in grout, beside the chart's right edge
    x_board = x_chart + cw + round(gap)
    y_board = y_chart + int(rng.integers(0, max(1, ch // 3)))
    if aligned:
        x_board = round(corners[1, 0] + 1.2 * pitch - 0.6 * t_pitch)
        y_board = round(corners[0, 1] - 0.6 * t_pitch)
    y_board = min(y_board, height - board_h - 1)
    tex[y_board:y_board + board_h, x_board:x_board + board_w] = rng.uniform(0.5, 0.8)
    tiles = rng.uniform(0.03, 0.85, (t_rows * t_cols, 3)) ** 1.5
    _paint_grid(tex, tiles, t_rows, t_cols,
                (x_board + 0.6 * t_pitch, y_board + 0.6 * t_pitch), t_pitch, 0.9)
    # a checkerboard of squares below the chart
    x_check, y_check = x_chart, y_chart + max(ch, board_h) + round(abs(gap))
    dark, light = rng.uniform(0.02, 0.08), rng.uniform(0.5, 0.9)
    for r in range(c_n):
        for c in range(c_n):
            y0, x0 = y_check + round(r * c_pitch), x_check + round(c * c_pitch)
            tex[y0:y0 + round(c_pitch), x0:x0 + round(c_pitch)] = dark if (r + c) % 2 else light
    # a grey card beside the checkerboard
    x_card = min(x_check + check_side + round(abs(gap)), width - card - 1)
    tex[y_check:y_check + card, x_card:x_card + card] = 0.18
    return tex, corners


def _warp_into(background: np.ndarray, texture: np.ndarray, h: np.ndarray) -> np.ndarray:
    import cv2

    height, width = background.shape[:2]
    warped = cv2.warpPerspective(texture.astype(np.float32), h, (width, height),
                                 flags=cv2.INTER_LINEAR)
    mask = cv2.warpPerspective(np.ones(texture.shape[:2], np.float32), h, (width, height),
                               flags=cv2.INTER_LINEAR)[..., None]
    return np.asarray(background * (1 - mask) + warped * mask, np.float32)


def _occluder_mask(shape: tuple[int, int], a: np.ndarray, b: np.ndarray, pitch: float,
                   rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """A leaf (two circular arcs meeting in points) or a hand (a palm and fingers) over the
    image points ``a`` and ``b`` (two neighbouring patch centres)."""
    import cv2

    mask = np.zeros(shape, np.uint8)
    axis = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
    normal = np.array([-axis[1], axis[0]])
    mid = (a + b) / 2.0 + rng.uniform(-0.08, 0.08, 2) * pitch
    shape_kind = "leaf" if rng.uniform() < 0.5 else "hand"
    if shape_kind == "leaf":
        half = 1.05 * pitch * rng.uniform(0.95, 1.1)  # tip to tip beyond both patches
        width = 0.5 * pitch * rng.uniform(0.9, 1.05)
        t = np.linspace(-1, 1, 60)
        along = t * half
        across = width * (1 - t ** 2) ** 0.8 * (1 + 0.08 * np.sin(9 * t))
        pts = np.concatenate([mid + along[:, None] * axis + across[:, None] * normal,
                              (mid + along[:, None] * axis - across[:, None] * normal)[::-1]])
        cv2.fillPoly(mask, [np.rint(pts).astype(np.int32)], 1)
        stalk = mid + 1.05 * half * axis
        cv2.line(mask, tuple(int(v) for v in np.rint(stalk)),
                 tuple(int(v) for v in np.rint(stalk + 0.5 * pitch * (axis + normal))), 1,
                 max(1, round(0.06 * pitch)))
    else:
        # palm over the two patches, fingers reaching off the chart's side
        palm = (int(0.95 * pitch), int(0.5 * pitch))
        angle = math.degrees(math.atan2(axis[1], axis[0]))
        cv2.ellipse(mask, tuple(int(v) for v in np.rint(mid)), palm, angle, 0, 360, 1, -1)
        for k in range(4):
            base = mid + (k - 1.5) * 0.42 * pitch * axis + 0.3 * pitch * normal
            tip = base + pitch * rng.uniform(1.0, 1.6) * normal
            cv2.line(mask, tuple(int(v) for v in np.rint(base)),
                     tuple(int(v) for v in np.rint(tip)), 1, max(1, round(0.3 * pitch)))
    return mask, shape_kind


def _isp(srgb: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict[str, float]]:
    """Local tone mapping (CLAHE on L*) and unsharp masking of an 8-bit sRGB frame."""
    import cv2

    clip = float(rng.uniform(3.0, 5.0))
    amount = float(rng.uniform(1.0, 2.5))
    radius = float(rng.uniform(1.5, 3.0))
    lab = cv2.cvtColor(srgb, cv2.COLOR_RGB2LAB)
    clahe = cv2.createCLAHE(clipLimit=clip, tileGridSize=(8, 8))
    lab[..., 0] = clahe.apply(lab[..., 0])
    toned = cv2.cvtColor(lab, cv2.COLOR_LAB2RGB).astype(np.float32)
    blurred = cv2.GaussianBlur(toned, (0, 0), radius)
    sharp = np.clip(toned + amount * (toned - blurred), 0, 255)
    return np.rint(sharp).astype(np.uint8), {"clahe_clip": round(clip, 2),
                                             "unsharp_amount": round(amount, 2),
                                             "unsharp_radius_px": round(radius, 2)}


def hard_scene(hazard: str, background_path: str | None, patch_linear: np.ndarray, *,
               seed: int | tuple[int, ...], long_side: int | None = None,
               jpeg_quality: int | None = 85) -> Scene:
    """One seeded photo of a 24-patch chart with ``hazard`` (:data:`HAZARDS`).

    ``background_path`` a photo (None: a noisy grey table); ``long_side`` the image's long side
    (default 1920 for ``isp``, 1600 otherwise). ``conditions['occluded']`` lists the covered
    patches' indices (``occluder``)."""
    import cv2

    if hazard not in HAZARDS:
        raise ValueError(f"unknown hazard {hazard!r}")
    rng = np.random.default_rng(seed)
    side = long_side or (1920 if hazard == "isp" else 1600)
    if background_path is not None:
        bg = _background(background_path, side)
        if hazard == "isp":  # a 16:9 dashcam frame
            bg = cv2.resize(bg, (side, round(side * 9 / 16)), interpolation=cv2.INTER_AREA)
    else:
        bg = np.full((round(side * 0.75), side, 3), 0.2, np.float32)
        bg *= 1 + 0.05 * rng.standard_normal(bg.shape[:2] + (1,)).astype(np.float32)
    height, width = bg.shape[:2]
    cond: dict[str, float | str] = {"hazard": hazard, "width": width, "height": height}
    frac = {"distractors": 0.22, "occluder": 0.3, "isp": 0.07}[hazard] * rng.uniform(0.8, 1.3)
    width_px = max(frac * width, 80.0)
    cells = 6.5
    if hazard == "distractors":
        pitch = float(np.clip(width_px / cells, 16, 120))
        tex, tex_corners = _distractor_mat(patch_linear, pitch, rng)
        width_px *= tex.shape[1] / ((5 + 2 * FRAME) * pitch)
    else:
        pitch = float(np.clip(width_px / cells, 12, 120))
        tex, tex_corners = _chart(patch_linear, pitch)
    turn = float(rng.uniform(-0.3, 0.3))
    tilt = (float(rng.uniform(-0.35, 0.35)), float(rng.uniform(-0.35, 0.35)))
    size = (tex.shape[1] - 1, tex.shape[0] - 1)
    h = np.eye(3)
    for _ in range(60):
        centre = (rng.uniform(0.3, 0.7) * width, rng.uniform(0.3, 0.7) * height)
        h = chart_homography(size, (width, height), width_px, centre, turn, tilt)
        outline = _map(h, np.array([[0, 0], [size[0], 0], [size[0], size[1]], [0, size[1]]],
                                   float))
        if (outline.min(axis=0) >= 2).all() and outline[:, 0].max() < width - 2 \
                and outline[:, 1].max() < height - 2:
            break
        width_px *= 0.93
    img = _warp_into(bg, tex, h)
    corners = _map(h, tex_corners)
    pitch_px = float(min(np.linalg.norm(corners[1] - corners[0]) / 5,
                         np.linalg.norm(corners[2] - corners[3]) / 5,
                         np.linalg.norm(corners[3] - corners[0]) / 3,
                         np.linalg.norm(corners[2] - corners[1]) / 3))
    cond["pitch_px"] = round(pitch_px, 2)
    if hazard == "occluder":
        grid = np.stack(np.meshgrid(np.arange(6), np.arange(4)), -1).reshape(-1, 2).astype(float)
        g2i = cv2.getPerspectiveTransform(CORNER_CELLS.astype(np.float32),
                                          corners.astype(np.float32)).astype(np.float64)
        centres = _map(g2i, grid)
        k = int(rng.integers(18, 24)) if rng.uniform() < 0.5 else int(rng.integers(0, 24))
        r, c = divmod(k, 6)
        horizontal = rng.uniform() < 0.5
        if horizontal:
            c = min(c, 4)
        else:
            r = min(r, 2)
        first = r * 6 + c
        second = first + (1 if horizontal else 6)
        mask, kind = _occluder_mask((height, width), centres[first], centres[second], pitch_px,
                                    rng)
        # the occluder's surface: a crop of the photo itself, far from the chart
        sy, sx = int(rng.integers(0, height // 2)), int(rng.integers(0, width // 2))
        surface = np.roll(np.roll(bg, -sy, axis=0), -sx, axis=1) * rng.uniform(0.6, 1.4)
        tint = np.array([0.6, 1.0, 0.4], np.float32) if kind == "leaf" else \
            np.array([1.0, 0.72, 0.58], np.float32)
        surface = np.clip(0.5 * surface + 0.5 * float(np.mean(surface)) * tint * 1.5, 0, 1)
        soft = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 0.8)[..., None]
        img = np.asarray(img * (1 - soft) + surface * soft, np.float32)
        # covered: more than a tenth of the patch's central half-pitch window
        yy, xx = np.mgrid[0:height, 0:width]
        covered = []
        for j, (x, y) in enumerate(centres):
            win = (np.abs(xx - x) <= 0.25 * pitch_px) & (np.abs(yy - y) <= 0.25 * pitch_px)
            if win.any() and mask[win].mean() > 0.1:
                covered.append(j)
        cond["occluded"] = ",".join(str(j) for j in covered)
        cond["occluder"] = kind
    exposure = float(rng.uniform(0.7, 1.2))
    img = img * np.float32(exposure)
    img = img + 0.005 * np.sqrt(np.maximum(img, 1e-4)) * rng.standard_normal(img.shape).astype(
        np.float32)
    srgb = np.clip(np.rint(cm.delinearize_srgb(np.clip(img, 0, 1)) * 255), 0, 255).astype(
        np.uint8)
    if hazard == "isp":
        srgb, isp = _isp(srgb, rng)
        cond.update(isp)
    data = None
    if jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", srgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        assert ok
        data = buf.tobytes()
        srgb = decode_jpeg(data)
    return Scene(srgb=srgb, kind="classic", corners=corners, pitch_px=pitch_px, conditions=cond,
                 jpeg=data)


__all__ = ["HAZARDS", "hard_scene"]
