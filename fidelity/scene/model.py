"""The chart scene model: geometry, materials, light, camera and expected values.

One description that every format writer (:mod:`fidelity.scene.gltf`, :mod:`fidelity.scene.usd`,
:mod:`fidelity.scene.mitsuba`) turns into its file, so the three exports show the same chart
from the same camera under the same light.

Conventions
-----------
- World: metres, right-handed, the chart in the plane z = 0 facing +z, +y up (as seen). The
  chart's centre is the origin; patch 0 (dark skin) is at the top left as seen from the camera.
- Geometry: the X-Rite ColorChecker Classic's outer size, 279.4 x 215.9 mm (11 x 8.5 in), with a
  4 x 6 field of 40 mm patches 4 mm apart centred on it (nominal, not a measured drawing; the
  colours do not depend on it); the ColorChecker Classic Mini's, 82.55 x 57.15 mm (3.25 x 2.25
  in, X-Rite's product sheet), with the Classic's patch field scaled to its width. The black frame is a rectangle of the chart's size 0.5 mm behind
  the patches (spectrally flat reflectance :data:`FRAME_REFLECTANCE`).
- Slanted-edge target (:class:`EdgeTarget`, ISO 12233:2017 e-SFR): beside the chart's right
  edge, a light square field (reflectance :data:`EDGE_LIGHT_REFLECTANCE`, spectrally flat) 0.5 mm
  behind the chart's plane, and on it a dark square (:data:`EDGE_DARK_REFLECTANCE`) turned
  :data:`EDGE_ANGLE_DEG` degrees counter-clockwise as seen, so that its four edges run 5 degrees
  off the pixel grid. The two reflectances make the edges' luminance ratio 0.8 / 0.2 = 4:1
  (ISO 12233:2017's e-SFR contrast). Sizes are shares of the chart's width (the Classic: a
  36.3 mm field, a 21.0 mm square, 1.7 mm from the chart), so the target scales with the chart
  and lands in the margin the default ``fill`` leaves in a 4:3 image.
- Light: one directional light along -z, so every patch receives the same irradiance (a flat
  chart facing the light has no shadow or inter-reflection). RGB renderers get a white light of
  irradiance ``pi * white_level`` (renderer units; Blender's W/m^2) or ``683 pi white_level``
  lux (glTF's photometric unit at 683 lm/W): a Lambertian patch of albedo rho then renders at
  ``rho * white_level``. Mitsuba gets the illuminant's SPD, scaled so that a perfect white
  reflector renders at Y = ``white_level``.
- Materials: RGB formats carry each patch's scene-consistent linear sRGB
  (:func:`fidelity.colour.spectral.scene_reference`: the patch spectrum under the illuminant,
  CIE 1931 2 degree observer, adapted to D65 by Bradford), clipped to [0, 1] (an albedo cannot
  be negative; the patches that clip and what it costs are in the manifest). Mitsuba carries the
  reflectance spectra themselves.
- Camera: a pinhole on the chart's axis looking at its centre (-z), ``width`` x ``height``
  pixels, vertical field of view ``yfov``, at the distance where the chart fills ``fill`` of
  the image along its tighter side (width or height). Pixel (row i, column j) is at x = j, y = i (the convention of
  ``fidelity gate --corners``), so the continuous image point (u, v) with u from the left edge
  is pixel x = u - 0.5.
"""

from __future__ import annotations

import math
from dataclasses import field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.camera.model import camera_response, ideal_sensitivities
from fidelity.colour.charts import load_chart
from fidelity.colour.colorimetry import (
    delinearize_srgb,
    delta_e_2000,
    lab_to_srgb,
    linearize_srgb,
    srgb_to_lab,
)
from fidelity.colour.spectral import (
    GRID_START_NM,
    load_illuminant,
    load_patch_spectra,
    scene_reference,
    wavelength_grid,
)
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.record import record

FloatArray = NDArray[np.float64]

#: Charts the scene can show (the same 24 patches at two physical sizes: :data:`GEOMETRIES`).
CHARTS: tuple[str, ...] = ("classic", "mini")
#: References the RGB materials can follow (``scene``: spectral; ``safecolor``: the Lab table).
REFERENCES: tuple[str, ...] = ("scene", "safecolor")
#: Reflectance of the black frame (spectrally flat, nominal).
FRAME_REFLECTANCE: float = 0.03
#: Luminous efficacy glTF importers use to turn lux into radiometric units (Blender: 683 lm/W).
LUMENS_PER_WATT: float = 683.0
#: Spectral step of the Mitsuba spectra, nm (81 samples over 380-780 nm).
SPECTRAL_STEP_NM: float = 5.0
#: Reflectance of the edge target's dark square (spectrally flat).
EDGE_DARK_REFLECTANCE: float = 0.2
#: Reflectance of the edge target's light field (spectrally flat): 4:1 against the square.
EDGE_LIGHT_REFLECTANCE: float = 0.8
#: The edge target's square is turned this far from the chart's axes (degrees).
EDGE_ANGLE_DEG: float = 5.0
#: Side of the light field, the dark square and the gap to the chart, shares of chart width.
EDGE_FIELD_SHARE: float = 0.13
EDGE_SQUARE_SHARE: float = 0.075
EDGE_GAP_SHARE: float = 0.006
#: Depth of the light field (behind the chart's plane, as the frame), metres.
EDGE_FIELD_Z: float = -0.0005
#: Limits of the camera settings.
MAX_SIDE_PX: int = 16384
FOV_RANGE_DEG: tuple[float, float] = (1.0, 170.0)


@record
class ChartGeometry:
    """Physical layout of a rows x cols chart, metres: outer ``width`` x ``height``, square
    patches of side ``patch`` on a ``pitch`` grid centred on the chart."""

    name: str
    width: float
    height: float
    patch: float
    pitch: float
    rows: int = 4
    cols: int = 6

    def patch_centre(self, i: int) -> tuple[float, float]:
        """(x, y) of patch ``i`` (row-major, row 0 at the top), metres from the chart centre."""
        r, c = divmod(i, self.cols)
        x = (c - (self.cols - 1) / 2) * self.pitch
        y = ((self.rows - 1) / 2 - r) * self.pitch
        return x, y

    def to_json(self) -> dict[str, Any]:
        """The geometry in millimetres."""
        return {"name": self.name, "width_mm": self.width * 1e3, "height_mm": self.height * 1e3,
                "patch_mm": self.patch * 1e3, "gap_mm": (self.pitch - self.patch) * 1e3,
                "rows": self.rows, "cols": self.cols,
                "note": f"outer size of the ColorChecker {TITLES[self.name]}; nominal patch "
                        "field, centred"}


#: Product names of the charts.
TITLES = {"classic": "Classic", "mini": "Classic Mini"}
CLASSIC = ChartGeometry("classic", 0.2794, 0.2159, 0.040, 0.044)
#: The Mini: 3.25 x 2.25 in outside, the Classic's patch field scaled by 82.55 / 279.4.
MINI = ChartGeometry("mini", 0.08255, 0.05715, 0.040 * 0.08255 / 0.2794,
                     0.044 * 0.08255 / 0.2794)
#: Geometry of each chart in :data:`CHARTS`.
GEOMETRIES = {"classic": CLASSIC, "mini": MINI}


@record
class EdgeTarget:
    """The slanted-edge target beside the chart (module docstring).

    Attributes
    ----------
    centre
        World (x, y) of the field's and the square's centre, metres.
    field, square
        The light field's and the dark square's sides, metres.
    angle_deg
        The square's turn, degrees counter-clockwise as seen from the camera.
    dark, light
        The square's and the field's reflectances (spectrally flat, in (0, 1]).
    """

    centre: tuple[float, float]
    field: float
    square: float
    angle_deg: float = EDGE_ANGLE_DEG
    dark: float = EDGE_DARK_REFLECTANCE
    light: float = EDGE_LIGHT_REFLECTANCE

    def square_corners(self) -> FloatArray:
        """(4, 2) world (x, y) of the dark square's corners: top left, top right, bottom
        right, bottom left as seen (before the turn), turned by ``angle_deg``."""
        return self._corners(self.square, self.angle_deg)

    def field_corners(self) -> FloatArray:
        """(4, 2) world (x, y) of the light field's corners (not turned), same order."""
        return self._corners(self.field, 0.0)

    def _corners(self, side: float, angle_deg: float) -> FloatArray:
        h = side / 2
        local = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
        a = math.radians(angle_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return np.asarray(local @ rot.T + np.asarray(self.centre), np.float64)

    @property
    def luminance_ratio(self) -> float:
        """The light field's luminance over the dark square's (both spectrally flat)."""
        return self.light / self.dark


def edge_target(chart: ChartGeometry) -> EdgeTarget:
    """The edge target beside ``chart``'s right edge, vertically centred (module docstring)."""
    w = chart.width
    field_side = EDGE_FIELD_SHARE * w
    x = w / 2 + EDGE_GAP_SHARE * w + field_side / 2
    return EdgeTarget((x, 0.0), field_side, EDGE_SQUARE_SHARE * w)


@record
class SceneCamera:
    """A pinhole camera at (0, 0, ``distance``) looking along -z with +y up."""

    width: int
    height: int
    yfov: float
    distance: float

    @property
    def focal_px(self) -> float:
        """Focal length in pixels."""
        return self.height / 2 / math.tan(self.yfov / 2)

    @property
    def xfov(self) -> float:
        """Horizontal field of view, radians."""
        return 2 * math.atan(self.width / 2 / self.focal_px)

    def project(self, x: float, y: float, z: float = 0.0) -> tuple[float, float]:
        """Pixel coordinates (x right, y down; pixel centres on integers) of world point."""
        depth = self.distance - z
        u = self.width / 2 + self.focal_px * x / depth
        v = self.height / 2 - self.focal_px * y / depth
        return u - 0.5, v - 0.5

    def to_json(self) -> dict[str, Any]:
        """Resolution, fields of view (degrees), distance (m), focal length (px)."""
        return {"width": self.width, "height": self.height,
                "yfov_deg": math.degrees(self.yfov), "xfov_deg": math.degrees(self.xfov),
                "distance_m": self.distance, "focal_px": self.focal_px,
                "position_m": [0.0, 0.0, self.distance], "looks_along": [0.0, 0.0, -1.0],
                "up": [0.0, 1.0, 0.0], "projection": "pinhole, no distortion"}


@record
class ChartScene:
    """Everything a writer needs (see the module docstring for the conventions).

    ``albedo`` (24, 3) the linear sRGB base colours of the RGB formats, in [0, 1];
    ``reference_lab``, ``reference_linear``, ``reference_srgb`` (24, 3) the reference the
    render is measured against (unclipped); ``reflectance`` (24, N) and ``illuminant_spd`` (N,)
    on the grid from 380 nm in ``step`` nm (Mitsuba); ``spectral_linear`` (24, 3) the closed
    form's linear sRGB of the spectral scene (not adapted to D65) at ``white_level``;
    ``clipped`` (24,) which patches' albedo was clipped; ``edge`` the slanted-edge target
    beside the chart (None: :func:`edge_target` of the chart, as :attr:`edge_target` gives).
    """

    chart: ChartGeometry
    camera: SceneCamera
    patch_names: tuple[str, ...]
    albedo: FloatArray
    reference_lab: FloatArray
    reference_linear: FloatArray
    reference_srgb: FloatArray
    clipped: NDArray[np.bool_]
    reflectance: FloatArray
    illuminant_spd: FloatArray
    spectral_linear: FloatArray
    illuminant: str
    reference: str
    white_level: float
    step: float = SPECTRAL_STEP_NM
    conventions: dict[str, Any] = field(default_factory=dict)
    edge: EdgeTarget | None = None

    @property
    def edge_target(self) -> EdgeTarget:
        """The slanted-edge target beside the chart (:func:`edge_target` of the chart)."""
        return self.edge if self.edge is not None else edge_target(self.chart)

    def edge_target_px(self) -> dict[str, Any]:
        """The edge target in the camera's image: ``square_corners_px`` and
        ``field_corners_px`` (4 x [x, y] each, the order of :meth:`EdgeTarget.square_corners`;
        pixel (row i, column j) at x = j, y = i) and ``in_image`` (the whole field inside the
        image)."""
        t, cam = self.edge_target, self.camera
        square = np.array([cam.project(x, y, 0.0) for x, y in t.square_corners()])
        fld = np.array([cam.project(x, y, EDGE_FIELD_Z) for x, y in t.field_corners()])
        inside = bool(np.all(fld >= -0.5) and np.all(fld[:, 0] <= cam.width - 0.5)
                      and np.all(fld[:, 1] <= cam.height - 0.5))
        return {"square_corners_px": square.tolist(), "field_corners_px": fld.tolist(),
                "in_image": inside}

    @property
    def irradiance(self) -> float:
        """Irradiance of the RGB light in renderer units (W/m^2 in Blender): pi * white_level."""
        return math.pi * self.white_level

    @property
    def illuminance_lux(self) -> float:
        """The same irradiance in lux at :data:`LUMENS_PER_WATT` (glTF's light unit)."""
        return self.irradiance * LUMENS_PER_WATT

    @property
    def exposure_ev(self) -> float:
        """The ``fidelity gate --exposure`` that maps the render back to albedo units."""
        return -math.log2(self.white_level)

    def patch_centres_px(self) -> FloatArray:
        """(24, 2) pixel (x, y) of every patch centre in the camera's image."""
        return np.array([self.camera.project(*self.chart.patch_centre(i))
                         for i in range(self.chart.rows * self.chart.cols)])

    def corners_px(self) -> FloatArray:
        """(4, 2) centres of the dark skin, bluish green, black and white patches (the order
        of ``fidelity gate --corners``)."""
        n = self.chart.cols
        last = self.chart.rows * n - 1
        return self.patch_centres_px()[[0, n - 1, last, last - n + 1]]

    def corners_option(self) -> str:
        """:meth:`corners_px` as the ``--corners X1,Y1,...,X4,Y4`` value."""
        return ",".join(f"{v:.2f}" for v in self.corners_px().ravel())

    def patch_size_px(self) -> float:
        """Side of a patch in the image, pixels."""
        return self.camera.focal_px * self.chart.patch / self.camera.distance

    def wavelengths(self) -> FloatArray:
        """Wavelengths (N,) of ``reflectance`` and ``illuminant_spd``, nm."""
        return np.asarray(GRID_START_NM + self.step * np.arange(self.illuminant_spd.size),
                          dtype=np.float64)


def make_camera(chart: ChartGeometry, width: int, height: int, yfov_deg: float,
                fill: float | None = None, distance: float | None = None) -> SceneCamera:
    """The camera at ``distance`` (metres) or where the chart fills ``fill`` (default 0.8)
    of the image along its tighter side (the width, unless the image is wider than the chart's
    aspect ratio), with bounds checked."""
    if not (16 <= width <= MAX_SIDE_PX and 16 <= height <= MAX_SIDE_PX):
        raise InvalidValueError(f"--resolution {width}x{height}: each side must be 16 to "
                                f"{MAX_SIDE_PX} pixels")
    lo, hi = FOV_RANGE_DEG
    if not (math.isfinite(yfov_deg) and lo <= yfov_deg <= hi):
        raise InvalidValueError(f"--fov {yfov_deg}: the vertical field of view must be "
                                f"{lo:g} to {hi:g} degrees")
    if fill is not None and distance is not None:
        raise InvalidValueError("--fill and --distance: give one of them, not both")
    yfov = math.radians(yfov_deg)
    focal = height / 2 / math.tan(yfov / 2)
    if distance is None:
        f = 0.8 if fill is None else fill
        if not (math.isfinite(f) and 0.05 <= f <= 1.0):
            raise InvalidValueError(f"--fill {fill}: the chart's share of the image width must "
                                    "be 0.05 to 1")
        distance = focal * max(chart.width / width, chart.height / height) / f
    if not (math.isfinite(distance) and distance > 0.01):
        raise InvalidValueError(f"--distance {distance}: must be more than 0.01 m")
    cam = SceneCamera(int(width), int(height), yfov, float(distance))
    half_h = focal * chart.height / 2 / distance
    half_w = focal * chart.width / 2 / distance
    if half_w > width / 2 or half_h > height / 2:
        raise InvalidValueError(f"--distance {distance:.4g} m: the chart does not fit in the "
                                "image; move the camera back or widen --fov")
    if cam.focal_px * chart.patch / distance < 4:
        raise InvalidValueError(f"--resolution {width}x{height}: patches would be smaller than "
                                "4 pixels; raise the resolution or move the camera closer")
    return cam


def build_scene(
    illuminant: str = "D65",
    reference: str = "scene",
    chart: str = "classic",
    *,
    resolution: tuple[int, int] = (640, 480),
    yfov_deg: float = 40.0,
    fill: float | None = None,
    distance: float | None = None,
    white_level: float = 1.0,
    spectra: str = "BabelColor Average",
) -> ChartScene:
    """The chart scene under ``illuminant`` with materials following ``reference``.

    ``resolution`` (width, height) pixels; ``yfov_deg`` the vertical field of view; ``fill``
    (share of the image the chart spans along its tighter side) or ``distance`` (metres) places the camera;
    ``white_level`` the linear value a perfect white reflector renders at (the white patch
    lands at its albedo times this).
    """
    if chart not in CHARTS:
        raise unknown_name("chart", chart, CHARTS)
    if reference not in REFERENCES:
        raise unknown_name("reference", reference, REFERENCES)
    if not (math.isfinite(white_level) and 1e-6 <= white_level <= 1e6):
        raise InvalidValueError(f"--white-level {white_level}: must be 1e-6 to 1e6")
    geometry = GEOMETRIES[chart]
    camera = make_camera(geometry, resolution[0], resolution[1], yfov_deg, fill, distance)
    ill = load_illuminant(illuminant)
    step = SPECTRAL_STEP_NM
    ps = load_patch_spectra(spectra)
    refl, spd = ps.on_grid(step), ill.on_grid(step)
    if reference == "scene":
        ref = scene_reference(ill, spectra)
        lab, linear, srgb = ref.lab, ref.linear_srgb, ref.srgb
        conv: dict[str, Any] = dict(ref.conventions)
    else:
        table = load_chart("safecolor")
        lab = np.asarray(table.lab, np.float64)
        srgb = np.asarray(lab_to_srgb(lab), np.float64)
        linear = np.asarray(linearize_srgb(srgb), np.float64)
        conv = {"reference": f"chart {table.name!r}: {table.title}",
                "provenance": table.provenance,
                "note": "RGB materials from the Lab table; the Mitsuba scene keeps the spectra"}
    albedo = np.clip(linear, 0.0, 1.0)
    clipped = np.any(albedo != linear, axis=1)
    # the closed form of what the Mitsuba scene holds: its 5 nm spectra, linearly interpolated
    # (as Mitsuba's 'regular' spectra are), integrated on the 1 nm grid of the CIE observer
    fine, coarse = wavelength_grid(1.0), wavelength_grid(step)
    refl_fine = np.stack([np.interp(fine, coarse, r) for r in refl])
    spectral_linear = camera_response(refl_fine, np.interp(fine, coarse, spd),
                                      ideal_sensitivities().values, 1.0) * white_level
    clip_de = None
    if clipped.any():
        clip_de = delta_e_2000(srgb_to_lab(_encode(albedo)), lab)
    conv.update({
        "rgb_materials": "linear sRGB (Rec. 709 primaries, D65 white) albedo = the reference's "
                         "linear sRGB clipped to [0, 1]",
        "albedo_clipping_delta_e": (None if clip_de is None else
                                    {"mean": float(np.mean(clip_de)),
                                     "max": float(np.max(clip_de))}),
    })
    return ChartScene(
        chart=geometry, camera=camera, patch_names=tuple(ps.patch_names), albedo=albedo,
        reference_lab=np.asarray(lab, np.float64), reference_linear=np.asarray(linear, np.float64),
        reference_srgb=np.asarray(srgb, np.float64), clipped=clipped, reflectance=refl,
        illuminant_spd=spd, spectral_linear=spectral_linear, illuminant=ill.name,
        reference=reference, white_level=float(white_level), step=step, conventions=conv,
        edge=edge_target(geometry),
    )


def _encode(linear: FloatArray) -> FloatArray:
    return np.asarray(delinearize_srgb(linear), np.float64)


__all__ = [
    "CHARTS",
    "CLASSIC",
    "EDGE_ANGLE_DEG",
    "EDGE_DARK_REFLECTANCE",
    "EDGE_FIELD_SHARE",
    "EDGE_FIELD_Z",
    "EDGE_GAP_SHARE",
    "EDGE_LIGHT_REFLECTANCE",
    "EDGE_SQUARE_SHARE",
    "EdgeTarget",
    "GEOMETRIES",
    "MINI",
    "FRAME_REFLECTANCE",
    "LUMENS_PER_WATT",
    "REFERENCES",
    "SPECTRAL_STEP_NM",
    "ChartGeometry",
    "ChartScene",
    "SceneCamera",
    "build_scene",
    "edge_target",
    "make_camera",
]
