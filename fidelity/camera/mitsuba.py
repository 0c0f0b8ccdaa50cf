"""Render the spectral chart with Mitsuba 3 (spectral variants) into camera raw RGB.

Why this agrees with the closed form: the chart is flat, convex and Lambertian, lit by one
directional emitter along its normal. Every point receives the same irradiance E(l) and no
light from any other surface (nothing can occlude or inter-reflect on a plane), so the
``direct`` integrator computes exactly L(l) = R(l) E(l) / pi per pixel; the camera channel is
the spectral integral ``int L(l) S_c(l) dl`` that ``specfilm`` estimates by Monte Carlo over
wavelengths. Multiplying by pi / sum(E ybar dl) gives the units of
:func:`fidelity.camera.model.camera_response`. Path tracing would add nothing but cost; what remains
is the wavelength-sampling noise of the Monte Carlo estimate, which the benchmark
(``benchmarks/speed/render.py``) measures against the closed form.

``specfilm`` needs non-negative channel sensitivities, so a channel with negative lobes (the
ideal camera's) is rendered as two channels, S+ = max(S, 0) and S- = max(-S, 0), and recombined
as S+ - S- (integration is linear).

Variant choice: ``llvm_ad_spectral`` (vectorised, JIT-compiled) needs libLLVM >= 16; with an
older one Dr.Jit aborts the whole process, so :func:`probe_variant` tries the variant in a
subprocess with ``DRJIT_LIBLLVM_PATH`` pointing at the newest libLLVM >= 16 it finds
(:func:`libllvm_candidates`: a user's ``DRJIT_LIBLLVM_PATH`` first, then the newest installed
one), and falls back to ``scalar_spectral`` (no LLVM needed). The variant that ran is reported.
"""

from __future__ import annotations

import copy
import os
import re
import subprocess
import sys
import time
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour.spectral import GRID_END_NM, GRID_START_NM, GRID_STEP_NM, cie_1931_cmfs
from fidelity.core import schema as sc
from fidelity.core.errors import FidelityError, InvalidValueError, unknown_name
from fidelity.core.fileio import display_path
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

FloatArray = NDArray[np.float64]

#: Variants in order of preference (the first that passes the probe runs).
PREFERRED_VARIANTS: tuple[str, ...] = ("llvm_ad_spectral", "scalar_spectral")

#: Defaults from benchmarks/speed/render.py (reports/render/): the cheapest samples per pixel
#: that keep every benchmarked camera within 0.02 mean ΔE00 of the closed form on both variants
#: (worst of 3 seeds: 0.012; 0.55 s on llvm_ad_spectral, 5.7 s on scalar_spectral, 2 cores),
#: at the closed form's layout of 32 px per patch (so seeded camera noise falls on the same
#: pixels in both renderers). Cheapest at any layout was 8 px / 144 spp (0.07 s, 0.019 ΔE00).
DEFAULT_SPP: int = 144
DEFAULT_PIXELS_PER_PATCH: int = 32

#: Sampler of the template (stratified per dimension, so the wavelength dimension converges much
#: faster than with "independent"; see reports/render/) and the samplers the benchmark sweeps.
DEFAULT_SAMPLER: str = "multijitter"
SAMPLERS: tuple[str, ...] = ("independent", "multijitter", "stratified", "ldsampler")

#: Minimum libLLVM major version for Dr.Jit's LLVM backend.
MIN_LLVM_VERSION: int = 16

_LIB_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)


class MitsubaUnavailableError(FidelityError):
    """No Mitsuba spectral variant can run on this machine."""


def _llvm_version(path: Path) -> int | None:
    m = re.search(r"libLLVM[-.]?(\d+)", path.name) or re.search(r"libLLVM\.so\.(\d+)", path.name)
    if m:
        return int(m.group(1))
    m = re.search(r"llvm-(\d+)", str(path))
    return int(m.group(1)) if m else None


def _installed_libllvm(min_version: int) -> list[tuple[int, Path]]:
    """(version, path) of libLLVM >= ``min_version`` in the usual folders, newest last."""
    candidates: list[tuple[int, Path]] = []
    dirs = [Path(d) for d in _LIB_DIRS] + sorted(Path("/usr/lib").glob("llvm-*/lib"))
    for d in dirs:
        if not d.is_dir():
            continue
        for p in d.glob("libLLVM*"):
            v = _llvm_version(p)
            if v is not None and v >= min_version and p.is_file():
                candidates.append((v, p))
    candidates.sort(key=lambda vp: (vp[0], -len(str(vp[1]))))
    return candidates


def find_libllvm(min_version: int = MIN_LLVM_VERSION) -> Path | None:
    """Newest libLLVM shared library with major version >= ``min_version``, or None.

    ``$DRJIT_LIBLLVM_PATH`` wins when it names an existing file. Otherwise the usual library
    folders (and ``/usr/lib/llvm-*/lib``) are searched for ``libLLVM-<N>.so`` /
    ``libLLVM.so.<N>`` / ``libLLVM.dylib``.
    """
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and Path(env).is_file():
        return Path(env)
    found = _installed_libllvm(min_version)
    return found[-1][1] if found else None


def libllvm_candidates(min_version: int = MIN_LLVM_VERSION) -> list[Path]:
    """Libraries to try for an LLVM variant, in order: ``$DRJIT_LIBLLVM_PATH`` (if it is a
    file), then the newest installed libLLVM >= ``min_version`` if that is another file."""
    out: list[Path] = []
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and Path(env).is_file():
        out.append(Path(env))
    found = _installed_libllvm(min_version)
    if found and all(found[-1][1].resolve() != p.resolve() for p in out):
        out.append(found[-1][1])
    return out


_PROBE_CODE = """
import sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
    "sensor": {"type": "orthographic", "film": {"type": "specfilm", "width": 4, "height": 4,
        "c": {"type": "regular", "wavelength_min": 400, "wavelength_max": 700,
              "values": "1, 1"}},
        "sampler": {"type": "independent", "sample_count": 1}},
    "emitter": {"type": "directional", "direction": [0, 0, -1]},
    "shape": {"type": "rectangle"}})
img = mi.render(scene)
print("probe-ok", float(mi.TensorXf(img).numpy().mean()) >= 0)
"""


@record
class VariantProbe:
    """Outcome of :func:`probe_variant`: the chosen ``variant``, the libLLVM used, and why."""

    variant: str
    libllvm: str | None
    notes: tuple[str, ...]


def _run_probe(variant: str, env: dict[str, str], timeout: float) -> tuple[bool, str]:
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE_CODE, variant], env=env, capture_output=True,
            text=True, timeout=timeout, check=False,
        )
    except subprocess.TimeoutExpired:
        return False, f"{variant}: probe timed out after {timeout:g} s"
    if proc.returncode == 0 and "probe-ok True" in proc.stdout:
        return True, f"{variant}: ok"
    tail = (proc.stderr.strip().splitlines() or ["no message"])[-1][:200]
    return False, f"{variant}: probe failed (exit {proc.returncode}: {tail})"


@lru_cache(maxsize=8)
def probe_variant(preferred: tuple[str, ...] = PREFERRED_VARIANTS, timeout: float = 120.0) -> VariantProbe:
    """Pick the first variant of ``preferred`` that renders a tiny scene in a subprocess.

    LLVM variants are tried with ``DRJIT_LIBLLVM_PATH`` set to each of
    :func:`libllvm_candidates` in turn. Raises :class:`MitsubaUnavailableError` when none works.
    The result is cached per process.
    """
    notes: list[str] = []
    for variant in preferred:
        if not variant.startswith("llvm"):
            ok, note = _run_probe(variant, dict(os.environ), timeout)
            notes.append(note)
            if ok:
                return VariantProbe(variant, None, tuple(notes))
            continue
        libs = libllvm_candidates()
        if not libs:
            notes.append(f"{variant}: skipped, no libLLVM >= {MIN_LLVM_VERSION} found")
        for lib in libs:
            ok, note = _run_probe(variant, dict(os.environ, DRJIT_LIBLLVM_PATH=str(lib)), timeout)
            notes.append(f"{note} [{lib}]")
            if ok:
                return VariantProbe(variant, str(lib), tuple(notes))
    raise MitsubaUnavailableError("no Mitsuba spectral variant works here: " + "; ".join(notes))


def _activate(variant: str) -> Any:
    """Import mitsuba with ``variant`` set (DRJIT_LIBLLVM_PATH set first for LLVM variants)."""
    lib: str | None = None
    if variant.startswith("llvm"):
        lib = probe_variant((variant,)).libllvm  # an unusable LLVM aborts the probe, not us
    elif "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = find_libllvm()
        lib = str(found) if found else None
    current = os.environ.get("DRJIT_LIBLLVM_PATH")
    if lib and current != lib:
        # Dr.Jit loads the library named here when it is imported (without one it retries when
        # an LLVM variant is first set). A different library already loaded would abort the
        # process on first use, so refuse instead of crashing.
        if "drjit" in sys.modules and current and variant.startswith("llvm"):
            raise MitsubaUnavailableError(
                f"Dr.Jit was imported with DRJIT_LIBLLVM_PATH={current}, which does not work "
                f"for {variant}; {lib} does: set DRJIT_LIBLLVM_PATH={lib} before starting, "
                "or use variant scalar_spectral"
            )
        if "drjit" not in sys.modules or not current:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
    import mitsuba as mi

    if variant not in mi.variants():
        raise InvalidValueError(f"Mitsuba variant {variant!r} is not built; have {mi.variants()}")
    mi.set_variant(variant)
    return mi


# --------------------------------------------------------------------------------------------
# Scene
# --------------------------------------------------------------------------------------------


def _plugin(*fields: sc.Field, required: bool = True) -> sc.Table:
    """A Mitsuba plugin table: its ``type`` and the fields the code reads; others pass."""
    return sc.Table(fields=(sc.Field("type", sc.String(nonempty=True), required=required),
                            *fields), extra=True)


#: The parts of the Mitsuba scene template that :func:`build_scene_dict` reads (the rest of a
#: template goes to Mitsuba as it is): the sensor with its film and sampler, the emitter, and
#: the ``patch`` shape with its BSDF.
TEMPLATE_SCHEMA = sc.Table(fields=(
    sc.Field("_comment", sc.AnyValue()),
    sc.Field("type", sc.String(choices=("scene",), ignore_case=False), required=True),
    sc.Field("sensor", _plugin(
        sc.Field("camera_height", sc.Number(lo=0.0, lo_open=True)),
        sc.Field("film", _plugin(), required=True),
        sc.Field("sampler", _plugin(), required=True)), required=True),
    sc.Field("emitter", _plugin(), required=True),
    sc.Field("patch", _plugin(sc.Field("bsdf", _plugin(), required=True)), required=True),
), extra=True)


def load_template(path: str | Path | None = None) -> dict[str, Any]:
    """The scene template (``scenes/spectral_chart.json`` unless ``path`` is given), checked
    against :data:`TEMPLATE_SCHEMA`."""
    p = Path(path) if path else resource_dir("scenes") / "spectral_chart.json"
    where = f"{display_path(p)} (Mitsuba scene template)"
    template: dict[str, Any] = sc.load_document(p, where, fmt="json", max_bytes=1 << 20,
                                                what="scene template")
    sc.validate(template, TEMPLATE_SCHEMA, where)
    return template


def _regular(values: ArrayLike, step: float) -> dict[str, Any]:
    v = np.asarray(values, dtype=np.float64)
    end = GRID_START_NM + step * (v.size - 1)
    return {"type": "regular", "wavelength_min": GRID_START_NM, "wavelength_max": end,
            "values": ", ".join(f"{x:.8g}" for x in v)}


def split_channels(sensitivities: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Split (N, 3) sensitivities into non-negative film channels (N, K) and a (3, K) recombination.

    camera = film @ recombination.T; channels that are identically zero are dropped.
    """
    s = np.asarray(sensitivities, dtype=np.float64)
    cols: list[FloatArray] = []
    rec: list[tuple[int, float]] = []
    for c in range(s.shape[1]):
        for sign in (1.0, -1.0):
            part = np.maximum(sign * s[:, c], 0.0)
            if np.any(part > 0):
                cols.append(part)
                rec.append((c, sign))
    recombine = np.zeros((s.shape[1], len(cols)))
    for k, (c, sign) in enumerate(rec):
        recombine[c, k] = sign
    return np.stack(cols, axis=1), recombine


def build_scene_dict(
    reflectance: ArrayLike,
    illuminant: ArrayLike,
    film_channels: ArrayLike,
    layout: Any,
    spp: int,
    step: float = GRID_STEP_NM,
    template: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Fill the template: patch rectangles, emitter SPD, film channels, sensor framing.

    ``reflectance`` (24, N), ``illuminant`` (N,), ``film_channels`` (N, K) on the grid;
    ``layout`` a :class:`fidelity.camera.render.ChartLayout` (1 world unit = 1 pixel).
    """
    import mitsuba as mi

    t = copy.deepcopy(template if template is not None else load_template())
    t.pop("_comment", None)
    patch = t.pop("patch")
    sensor = t["sensor"]
    height_above = float(sensor.pop("camera_height", 10.0))
    w, h = layout.width, layout.height
    # Orthographic: camera-space x in [-1, 1] spans the film width (y follows the aspect
    # ratio), so a uniform scale of w/2 frames the w x h chart exactly.
    sensor["to_world"] = mi.ScalarTransform4f().look_at(
        origin=[w / 2, h / 2, height_above], target=[w / 2, h / 2, 0.0], up=[0.0, 1.0, 0.0]
    ) @ mi.ScalarTransform4f().scale([w / 2, w / 2, 1.0])
    film = sensor["film"]
    film["width"], film["height"] = w, h
    fc = np.asarray(film_channels, dtype=np.float64)
    for k in range(fc.shape[1]):
        film[f"s{k:02d}"] = _regular(fc[:, k], step)
    sensor["sampler"]["sample_count"] = int(spp)
    t["emitter"]["irradiance"] = _regular(illuminant, step)
    refl = np.asarray(reflectance, dtype=np.float64)
    for i in range(refl.shape[0]):
        y0, y1, x0, x1 = layout.patch_box(i)
        # image row y counts down from the top; world y counts up.
        cx, cy = (x0 + x1) / 2, h - (y0 + y1) / 2
        shape = copy.deepcopy(patch)
        shape["to_world"] = mi.ScalarTransform4f().translate([cx, cy, 0.0]) @ (
            mi.ScalarTransform4f().scale([(x1 - x0) / 2, (y1 - y0) / 2, 1.0]))
        shape["bsdf"]["reflectance"] = _regular(refl[i], step)
        t[f"patch{i:02d}"] = shape
    return t


@record
class MitsubaImage:
    """A Mitsuba render in camera raw units (H, W, 3), with the variant, the samples per pixel
    that ran (a sampler may round the request), the sampler and the render time."""

    image: FloatArray
    variant: str
    libllvm: str | None
    spp: int
    sampler: str
    seconds_render: float
    probe_notes: tuple[str, ...]


def render_raw(
    reflectance: ArrayLike,
    illuminant: ArrayLike,
    sensitivities: ArrayLike,
    layout: Any,
    *,
    spp: int = DEFAULT_SPP,
    step: float = GRID_STEP_NM,
    variant: str | None = None,
    seed: int = 0,
    sampler: str | None = None,
) -> MitsubaImage:
    """Render the chart and return camera raw RGB in :func:`fidelity.camera.model.camera_response` units.

    raw_c = pi * film_c / sum(E ybar dl), film_c = sum_k recombine[c, k] * specfilm channel k.
    ``variant`` None probes (:func:`probe_variant`); ``seed`` seeds the sampler; ``sampler``
    a Mitsuba sampler plugin (default :data:`DEFAULT_SAMPLER`, from the template).
    """
    def scene(channels: FloatArray, template: dict[str, Any]) -> dict[str, Any]:
        return build_scene_dict(reflectance, illuminant, channels, layout, spp, step, template)

    return _render(scene, (layout.height, layout.width), illuminant, sensitivities, spp=spp,
                   step=step, variant=variant, seed=seed, sampler=sampler)


def build_target_dict(target: Any, illuminant: ArrayLike, film_channels: ArrayLike, spp: int,
                      step: float = GRID_STEP_NM, template: dict[str, Any] | None = None
                      ) -> dict[str, Any]:
    """The template filled with a slanted-edge target
    (:class:`fidelity.chart.turned.PaintedEdgeTarget`, 1 world unit = 1 pixel): a light
    rectangle over the whole film half a pixel behind a dark square of ``target.side_px``
    turned ``target.angle_deg`` (counter-clockwise in the image, y down: clockwise in world
    coordinates, y up), both spectrally flat at ``target.light`` and ``target.dark``."""
    import mitsuba as mi

    h, w = target.size
    n = np.asarray(illuminant).size
    square: dict[str, Any] = {"type": "rectangle", "bsdf": {"type": "diffuse"}}
    layout = _TargetFrame(h, w)
    t = build_scene_dict(np.zeros((0, n)), illuminant, film_channels, layout, spp,
                         step, template)
    # pixel (row i, column j) centre at world (j + 1/2, h - i - 1/2): the target's centre,
    # image ((w - 1) / 2, (h - 1) / 2), is world (w / 2, h / 2)
    field = copy.deepcopy(square)
    field["to_world"] = mi.ScalarTransform4f().translate([w / 2, h / 2, -0.5]) @ (
        mi.ScalarTransform4f().scale([w, h, 1.0]))
    field["bsdf"]["reflectance"] = _regular(np.full(n, float(target.light)), step)
    dark = copy.deepcopy(square)
    half = float(target.side_px) / 2
    dark["to_world"] = (mi.ScalarTransform4f().translate([w / 2, h / 2, 0.0])
                        @ mi.ScalarTransform4f().rotate([0.0, 0.0, 1.0], -float(target.angle_deg))
                        @ mi.ScalarTransform4f().scale([half, half, 1.0]))
    dark["bsdf"]["reflectance"] = _regular(np.full(n, float(target.dark)), step)
    t["edge_field"], t["edge_square"] = field, dark
    return t


@record
class _TargetFrame:
    """The film of a target render, as :func:`build_scene_dict` reads a layout (no patches)."""

    height: int
    width: int


def render_target_raw(
    target: Any,
    illuminant: ArrayLike,
    sensitivities: ArrayLike,
    *,
    spp: int = DEFAULT_SPP,
    step: float = GRID_STEP_NM,
    variant: str | None = None,
    seed: int = 0,
    sampler: str | None = None,
) -> MitsubaImage:
    """Render a slanted-edge target (:func:`build_target_dict`) and return camera raw RGB in
    :func:`fidelity.camera.model.camera_response` units, as :func:`render_raw` does for the
    chart (the template's box pixel filter: each pixel the average over its area).

    Parameters
    ----------
    target
        A :class:`fidelity.chart.turned.PaintedEdgeTarget` (its size, square, turn and
        reflectances).
    illuminant, sensitivities
        The illuminant's SPD ``(N,)`` and the camera's sensitivities ``(N, 3)`` on the grid.
    spp, step, variant, seed, sampler
        As for :func:`render_raw`.

    Returns
    -------
    MitsubaImage
        The raw image ``target.size + (3,)``.
    """
    def scene(channels: FloatArray, template: dict[str, Any]) -> dict[str, Any]:
        return build_target_dict(target, illuminant, channels, spp, step, template)

    return _render(scene, tuple(target.size), illuminant, sensitivities, spp=spp, step=step,
                   variant=variant, seed=seed, sampler=sampler)


def _render(scene_dict: Any, size: tuple[int, int], illuminant: ArrayLike,
            sensitivities: ArrayLike, *, spp: int, step: float, variant: str | None,
            seed: int, sampler: str | None) -> MitsubaImage:
    """Activate a variant, fill the template by ``scene_dict(film channels, template)``,
    render ``size`` (H, W) and recombine the film's channels to camera raw units."""
    if spp < 1:
        raise InvalidValueError(f"spp must be >= 1, got {spp}")
    probe = probe_variant() if variant is None else probe_variant((variant,))
    try:
        mi = _activate(probe.variant)
    except MitsubaUnavailableError as exc:
        fallback = [v for v in PREFERRED_VARIANTS if not v.startswith("llvm")]
        if variant is not None or not fallback:
            raise
        probe = probe_variant(tuple(fallback))
        probe = VariantProbe(probe.variant, None, (*probe.notes, f"in-process: {exc}"))
        mi = _activate(probe.variant)
    channels, recombine = split_channels(sensitivities)
    e = np.asarray(illuminant, dtype=np.float64)
    template = load_template()
    if sampler is not None:
        if sampler not in SAMPLERS:
            raise unknown_name("Mitsuba sampler", sampler, SAMPLERS)
        template["sensor"]["sampler"]["type"] = sampler
    used_sampler = template["sensor"]["sampler"]["type"]
    scene = mi.load_dict(scene_dict(channels, template))
    # some samplers round the sample count (multijitter: to a w x h grid); report what ran
    effective_spp = int(scene.sensors()[0].sampler().sample_count())
    t0 = time.perf_counter()
    img = np.asarray(mi.render(scene, seed=int(seed), spp=effective_spp), dtype=np.float64)
    seconds = time.perf_counter() - t0
    norm = float(e @ cie_1931_cmfs(step)[:, 1]) * step
    raw = (img.reshape(size[0], size[1], -1) @ recombine.T) * (np.pi / norm)
    return MitsubaImage(raw, probe.variant, probe.libllvm, effective_spp, used_sampler, seconds,
                        probe.notes)


__all__ = [
    "DEFAULT_PIXELS_PER_PATCH",
    "DEFAULT_SAMPLER",
    "SAMPLERS",
    "DEFAULT_SPP",
    "TEMPLATE_SCHEMA",
    "GRID_END_NM",
    "PREFERRED_VARIANTS",
    "MitsubaImage",
    "MitsubaUnavailableError",
    "VariantProbe",
    "build_scene_dict",
    "build_target_dict",
    "find_libllvm",
    "libllvm_candidates",
    "load_template",
    "probe_variant",
    "render_raw",
    "render_target_raw",
    "split_channels",
]
