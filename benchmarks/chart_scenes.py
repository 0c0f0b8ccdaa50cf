"""Synthetic photos of colour charts with known geometry, for the chart-finding benchmark and tests.

A chart is drawn flat in its own plane (a texture), then composited into a background through a
homography built from a 3-D tilt, an in-plane turn and a pinhole projection, so the true image
positions of the corner patch centres (dark skin, bluish green, black, white) are known in
closed form. Everything is done in linear light; the result is encoded as 8-bit sRGB (and, in
the benchmark, JPEG-compressed) like a photo.

Chart kinds (:data:`KINDS`):

``classic``
    the 24-patch ColorChecker layout (4 x 6 patches, 0.84-pitch patches, a black frame
    0.75 pitch beyond the outer patch centres);
``mini``
    the same layout, smaller in the image;
``passport``
    two pages side by side in a dark grey case: a page of 4 x 5 smaller patches of other
    colours (skin tones, greys: a Passport's other page, not the 24-patch layout) and the
    24-patch page; the truth is the 24-patch page;
``sg``
    a 10 x 14 grid of 140 patches whose central 4 x 6 block holds the 24 ColorChecker colours
    (like a ColorChecker SG): a chart that fidelity must refuse, not measure;
``none``
    no chart.

Everything is seeded: :func:`make_scene` with the same arguments gives the same image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fidelity.colour import colorimetry as cm

#: Chart kinds drawn here.
KINDS = ("classic", "mini", "passport", "sg", "none")
#: Side of a patch in patch pitches.
PATCH_FRACTION = 0.84
#: Frame beyond the outer patch centres, in patch pitches.
FRAME = 0.75
#: Linear value of the chart's black frame and of the Passport's case.
FRAME_LINEAR = 0.025
CASE_LINEAR = 0.06
#: Grid cells of the corner patches (dark skin, bluish green, black, white), (u, v).
CORNER_CELLS = np.array([[0, 0], [5, 0], [5, 3], [0, 3]], dtype=float)


@dataclass(frozen=True)
class Scene:
    """A synthetic photo: ``srgb`` ``(H, W, 3)`` uint8, and where its 24-patch chart is.

    ``corners`` ``(4, 2)`` image ``(x, y)`` of the dark skin, bluish green, black and white
    patch centres (``None`` without a 24-patch chart); ``pitch_px`` the smallest patch pitch
    along the chart's edges; ``conditions`` what was done to the image (for the report).
    """

    srgb: np.ndarray
    kind: str
    corners: np.ndarray | None
    pitch_px: float
    conditions: dict[str, float | str]
    jpeg: bytes | None = None


def _paint_grid(texture: np.ndarray, colours: np.ndarray, rows: int, cols: int,
                origin: tuple[float, float], pitch: float, fraction: float = PATCH_FRACTION
                ) -> None:
    """Paint ``rows`` x ``cols`` square patches (row-major ``colours``) into ``texture``;
    cell ``(c, r)`` is centred at ``origin + (c, r) * pitch`` (texture pixels, centres at
    integers)."""
    half = fraction * pitch / 2.0
    for r in range(rows):
        for c in range(cols):
            x, y = origin[0] + c * pitch, origin[1] + r * pitch
            x0, x1 = int(math.ceil(x - half)), int(math.floor(x + half))
            y0, y1 = int(math.ceil(y - half)), int(math.floor(y + half))
            texture[y0:y1 + 1, x0:x1 + 1] = colours[r * cols + c]


def chart_texture(kind: str, patch_linear: np.ndarray, pitch: float, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The chart of ``kind`` drawn flat: ``(texture (h, w, 3) linear, corner centres (4, 2))``.

    ``patch_linear`` ``(24, 3)`` linear RGB of the 24 patches; ``pitch`` the patch pitch in
    texture pixels; the corner centres are texture ``(x, y)`` of the 24-patch chart's dark
    skin, bluish green, black and white patches.
    """
    if kind in ("classic", "mini"):
        w, h = round((5 + 2 * FRAME) * pitch), round((3 + 2 * FRAME) * pitch)
        tex = np.full((h + 1, w + 1, 3), FRAME_LINEAR)
        origin = (FRAME * pitch, FRAME * pitch)
        _paint_grid(tex, patch_linear, 4, 6, origin, pitch)
        return tex, origin + CORNER_CELLS * pitch
    if kind == "passport":
        page_w, page_h = (5 + 2 * FRAME) * pitch, (3 + 2 * FRAME) * pitch
        gap = 0.6 * pitch
        w, h = round(2 * page_w + 3 * gap), round(page_h + 2 * gap)
        tex = np.full((h + 1, w + 1, 3), CASE_LINEAR)
        # the other page: light grey with 4 x 5 smaller patches of skin tones and greys
        x_other = gap
        tex[round(gap):round(gap + page_h), round(x_other):round(x_other + page_w)] = 0.45
        skin = np.array([[0.45, 0.30, 0.22], [0.60, 0.42, 0.33], [0.30, 0.18, 0.12],
                         [0.70, 0.55, 0.45], [0.20, 0.12, 0.08]])
        greys = np.linspace(0.05, 0.8, 5)[:, None] * np.ones(3)
        tints = np.array([[0.4, 0.42, 0.5], [0.5, 0.45, 0.38], [0.35, 0.4, 0.36],
                          [0.45, 0.38, 0.45], [0.55, 0.52, 0.42]])
        other = np.concatenate([skin, greys, tints, skin[::-1] * 0.8])
        other = other[rng.permutation(len(other))]
        small = 0.8 * pitch
        _paint_grid(tex, other, 4, 5, (x_other + (page_w - 4 * small) / 2,
                                       gap + (page_h - 3 * small) / 2), small)
        # the 24-patch page: black, like the classic chart
        x_chart = 2 * gap + page_w
        tex[round(gap):round(gap + page_h), round(x_chart):round(x_chart + page_w)] = FRAME_LINEAR
        origin = (x_chart + FRAME * pitch, gap + FRAME * pitch)
        _paint_grid(tex, patch_linear, 4, 6, origin, pitch)
        return tex, origin + CORNER_CELLS * pitch
    if kind == "sg":
        rows, cols = 10, 14
        w, h = round((cols - 1 + 2 * FRAME) * pitch), round((rows - 1 + 2 * FRAME) * pitch)
        tex = np.full((h + 1, w + 1, 3), FRAME_LINEAR)
        colours = rng.uniform(0.03, 0.85, (rows * cols, 3)) ** 1.5
        grid = colours.reshape(rows, cols, 3)
        grid[3:7, 4:10] = patch_linear.reshape(4, 6, 3)
        # neutral border patches, as on an SG
        grid[0, :] = np.linspace(0.03, 0.9, cols)[:, None]
        grid[-1, :] = np.linspace(0.9, 0.03, cols)[:, None]
        _paint_grid(tex, grid.reshape(-1, 3), rows, cols, (FRAME * pitch, FRAME * pitch), pitch)
        return tex, (FRAME * pitch + 4 * pitch, FRAME * pitch + 3 * pitch) + CORNER_CELLS * pitch
    raise ValueError(f"unknown chart kind {kind!r}")


def chart_homography(texture_size: tuple[int, int], image_size: tuple[int, int],
                     width_px: float, centre: tuple[float, float], turn: float,
                     tilt: tuple[float, float], distance: float = 2.5) -> np.ndarray:
    """Texture ``(x, y)`` -> image ``(x, y)``: the flat chart tilted by ``tilt`` (radians about
    its x and y axes), turned by ``turn`` in the image plane and seen by a pinhole camera at
    ``distance`` chart widths, its centre at ``centre`` and about ``width_px`` wide."""
    tw, th = texture_size
    corners = np.array([[0, 0], [tw, 0], [tw, th], [0, th]], dtype=float)
    plane = (corners - (tw / 2, th / 2)) / tw  # chart width 1, centred
    ax, ay = tilt
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    c, s = math.cos(turn), math.sin(turn)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    pts = np.c_[plane, np.zeros(4)] @ (rz @ ry @ rx).T
    proj = pts[:, :2] / (1.0 + pts[:, 2:3] / distance)
    proj = proj * width_px + centre
    import cv2

    h = cv2.getPerspectiveTransform(corners.astype(np.float32), proj.astype(np.float32))
    del image_size
    return np.asarray(h, dtype=np.float64)


def _map(h: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = np.c_[pts, np.ones(len(pts))] @ h.T
    return np.asarray(p[:, :2] / p[:, 2:], dtype=np.float64)


def composite(background: np.ndarray, texture: np.ndarray, h: np.ndarray,
              shading: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Warp the linear ``texture`` into the linear ``background`` through ``h`` (anti-aliased
    edges), with a linear illumination gradient ``shading`` (fraction per chart width along
    the image's x and y) over the chart."""
    import cv2

    height, width = background.shape[:2]
    mask_tex = np.ones(texture.shape[:2], np.float32)
    warped = cv2.warpPerspective(texture.astype(np.float32), h, (width, height),
                                 flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    mask = cv2.warpPerspective(mask_tex, h, (width, height), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT)[..., None]
    if shading != (0.0, 0.0):
        ys, xs = np.nonzero(mask[..., 0] > 0)
        if len(xs):
            span = max(float(np.ptp(xs)), 1.0)
            cx, cy = xs.mean(), ys.mean()
            yy, xx = np.mgrid[0:height, 0:width]
            gain = 1.0 + shading[0] * (xx - cx) / span + shading[1] * (yy - cy) / span
            warped = warped * np.clip(gain, 0.3, 2.0)[..., None].astype(np.float32)
    return np.asarray(background * (1.0 - mask) + warped * mask, dtype=np.float32)


def _background(path: str, long_side: int) -> np.ndarray:
    """A COCO photo as linear RGB, resized (cubic) to ``long_side`` pixels on its long side."""
    import cv2
    from PIL import Image

    with Image.open(path) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.float32) / 255.0
    height, width = rgb.shape[:2]
    s = long_side / max(height, width)
    if abs(s - 1.0) > 1e-6:
        rgb = np.asarray(cv2.resize(rgb, (round(width * s), round(height * s)),
                                    interpolation=cv2.INTER_CUBIC if s > 1 else cv2.INTER_AREA),
                         dtype=np.float32)
    return cm.linearize_srgb(np.clip(rgb, 0.0, 1.0)).astype(np.float32)


#: Light colours (linear RGB gains of the whole scene): white, tungsten, shade, fluorescent.
LIGHTS = {"neutral": (1.0, 1.0, 1.0), "warm": (1.0, 0.78, 0.5), "cool": (0.78, 0.9, 1.0),
          "green": (0.85, 1.0, 0.75), "magenta": (1.0, 0.8, 0.95)}


def make_scene(kind: str, background_path: str | None, patch_linear: np.ndarray, *,
               seed: int | tuple[int, ...], long_side: int = 1600,
               jpeg: bool = True, hard: bool = True, noise_seed: int | None = None,
               noise_level: float | None = None) -> Scene:
    """One seeded synthetic photo (see the module docstring).

    ``background_path`` a photo (``None``: a noisy grey table with a few coloured boxes);
    ``patch_linear`` the 24 patches' linear RGB; ``hard`` adds the harder conditions (coloured
    light, clipping, blur, occlusion, strong tilt) at random; ``noise_seed``: the sensor
    noise drawn from a generator of its own (the same scene, another capture), else from the
    scene's; ``noise_level``: its scale (default: drawn, 0.002 to 0.02).
    """
    import cv2

    rng = np.random.default_rng(seed)
    if background_path is not None:
        bg = _background(background_path, long_side)
    else:
        w, hgt = long_side, round(long_side * 0.75)
        bg = np.full((hgt, w, 3), 0.2, np.float32) * (1 + 0.05 * rng.standard_normal((hgt, w, 1)))
        for _ in range(4):
            x0, y0 = rng.integers(0, w - 20), rng.integers(0, hgt - 20)
            bg[y0:y0 + rng.integers(10, hgt // 3), x0:x0 + rng.integers(10, w // 3)] = \
                rng.uniform(0.02, 0.7, 3)
        bg = bg.astype(np.float32)
    height, width = bg.shape[:2]
    cond: dict[str, float | str] = {"width": width, "height": height}
    corners = None
    pitch_px = math.nan
    img = bg
    if kind != "none":
        frac_range = {"classic": (0.15, 0.6), "mini": (0.06, 0.15), "passport": (0.35, 0.8),
                      "sg": (0.3, 0.7)}[kind]
        frac = math.exp(rng.uniform(math.log(frac_range[0]), math.log(frac_range[1])))
        min_width = {"classic": 110, "mini": 90, "passport": 230, "sg": 250}[kind]
        width_px = min(max(frac * width, min_width), 0.9 * min(width, height) * 1.45)
        turn = rng.uniform(-0.35, 0.35) if rng.uniform() < 0.6 else rng.uniform(-math.pi, math.pi)
        max_tilt = 0.9 if hard else 0.35
        tilt = (rng.uniform(-max_tilt, max_tilt), rng.uniform(-max_tilt, max_tilt))
        cells = {"classic": 6.5, "mini": 6.5, "passport": 15.0, "sg": 14.5}[kind]
        tex_pitch = float(np.clip(width_px / cells, 16, 120))
        tex, tex_corners = chart_texture(kind, patch_linear, tex_pitch, rng)
        size = (tex.shape[1] - 1, tex.shape[0] - 1)
        for _ in range(50):  # a placement whose chart lies within the image
            centre = (rng.uniform(0.1, 0.9) * width, rng.uniform(0.1, 0.9) * height)
            h = chart_homography(size, (width, height), width_px, centre, turn, tilt)
            outline = _map(h, np.array([[0, 0], [size[0], 0], [size[0], size[1]], [0, size[1]]],
                                       float))
            if (outline.min(axis=0) >= 2).all() and (outline[:, 0].max() < width - 2) \
                    and (outline[:, 1].max() < height - 2):
                break
            width_px *= 0.95
        shading = (rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)) if hard else (0.0, 0.0)
        img = composite(bg, tex, h, shading)
        corners = _map(h, tex_corners)
        pitch_px = float(min(np.linalg.norm(corners[1] - corners[0]) / 5,
                             np.linalg.norm(corners[2] - corners[3]) / 5,
                             np.linalg.norm(corners[3] - corners[0]) / 3,
                             np.linalg.norm(corners[2] - corners[1]) / 3))
        cond.update(chart_width_px=round(width_px, 1), turn_deg=round(math.degrees(turn), 1),
                    tilt_deg=f"{math.degrees(tilt[0]):.0f},{math.degrees(tilt[1]):.0f}",
                    pitch_px=round(pitch_px, 2))
        if hard and rng.uniform() < 0.25:  # occlusion: a blob of background colour over the chart
            inside = corners.mean(axis=0) + rng.uniform(-0.5, 0.5, 2) * (corners[1] - corners[0])
            axes = (int(rng.uniform(0.4, 1.0) * pitch_px), int(rng.uniform(0.8, 2.5) * pitch_px))
            colour = bg[rng.integers(0, height), rng.integers(0, width)].astype(float)
            mask = np.zeros((height, width), np.uint8)
            cv2.ellipse(mask, (int(inside[0]), int(inside[1])), axes, float(rng.uniform(0, 180)),
                        0, 360, 1, -1)
            img = np.where(mask[..., None] > 0, colour.astype(np.float32), img)
            cond["occluded"] = "yes"
    light = "neutral"
    if hard and rng.uniform() < 0.5:
        light = str(rng.choice(list(LIGHTS)[1:]))
    exposure = math.exp(rng.uniform(math.log(0.5), math.log(2.5 if hard else 1.2)))
    img = img * np.asarray(LIGHTS[light], np.float32) * np.float32(exposure)
    cond.update(light=light, exposure=round(exposure, 3))
    if hard and rng.uniform() < 0.4:
        sigma = rng.uniform(0.6, 2.5) * max(1.0, width / 1600)
        img = cv2.GaussianBlur(img, (0, 0), sigma)
        cond["blur_sigma_px"] = round(sigma, 2)
    noise = rng.uniform(0.002, 0.02)
    if noise_level is not None:
        noise = noise_level
    draw = rng if noise_seed is None else np.random.default_rng(noise_seed)
    img = img + noise * np.sqrt(np.maximum(img, 1e-4)) * draw.standard_normal(img.shape).astype(
        np.float32)
    cond["noise"] = round(noise, 4)
    srgb = np.clip(np.rint(cm.delinearize_srgb(np.clip(img, 0, 1)) * 255), 0, 255).astype(np.uint8)
    data = None
    if jpeg:
        quality = int(rng.integers(45, 96))
        ok, buf = cv2.imencode(".jpg", srgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
        assert ok
        data = buf.tobytes()
        srgb = decode_jpeg(data)
        cond["jpeg_quality"] = quality
    return Scene(srgb=srgb, kind=kind, corners=None if kind in ("none", "sg") else corners,
                 pitch_px=pitch_px, conditions=cond, jpeg=data)


def decode_jpeg(data: bytes) -> np.ndarray:
    """``(H, W, 3)`` uint8 RGB of JPEG bytes (OpenCV's decoder, as in :func:`make_scene`)."""
    import cv2

    bgr = np.asarray(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
    return np.ascontiguousarray(bgr[..., ::-1])


def corners_correct(found: np.ndarray | None, truth: np.ndarray, pitch_px: float,
                    tolerance: float = 0.5) -> bool:
    """Whether the four corner patch centres found lie within ``tolerance`` patch pitches of the
    truth (in the right order)."""
    if found is None:
        return False
    err = np.linalg.norm(np.asarray(found, float) - truth, axis=-1)
    return bool(np.all(err <= tolerance * pitch_px))


__all__ = ["KINDS", "LIGHTS", "Scene", "chart_homography", "chart_texture", "composite",
           "corners_correct", "decode_jpeg", "make_scene"]
