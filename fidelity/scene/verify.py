"""Check a render of an exported scene: sample its patches at the manifest's centres and run
Blender on an export (Blender is a third-party renderer here, run as its own process).

``bpy`` (the Blender wheel) pins numpy < 2 while fidelity's colour stack needs numpy >= 2, so
the two cannot share one environment: Blender runs in a separate Python (``$FIDELITY_BPY_PYTHON``,
e.g. a virtual environment with ``pip install bpy``) or as the ``blender`` program
(``$FIDELITY_BLENDER``), with ``scenes/blender_render.py``.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.colour.colorimetry import delta_e_2000, linear_srgb_to_xyz, xyz_to_lab
from fidelity.core.errors import FidelityError
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

FloatArray = NDArray[np.float64]


#: The folder (in a checkout, beside ``fidelity/``) of the Python environment with ``bpy``.
BLENDER_VENV = ".venv-blender"


class BlenderUnavailableError(FidelityError):
    """No Python with ``bpy`` and no ``blender`` program was found."""


def patch_linear_means(pixels: ArrayLike, centres: ArrayLike, side_px: float,
                       fraction: float = 0.5) -> FloatArray:
    """Mean linear RGB (n, 3) of a square window of ``fraction`` x ``side_px`` pixels about each
    of the (n, 2) pixel ``centres`` (x, y; pixel (row i, column j) at x = j, y = i) of the
    (H, W, 3) ``pixels``. Negative values are kept (out-of-gamut colours)."""
    img = np.asarray(pixels, dtype=np.float64)
    half = max(0.5, fraction * side_px / 2)
    out = np.empty((len(np.asarray(centres)), 3))
    for k, (x, y) in enumerate(np.asarray(centres, dtype=np.float64)):
        x0, x1 = int(np.ceil(x - half)), int(np.floor(x + half)) + 1
        y0, y1 = int(np.ceil(y - half)), int(np.floor(y + half)) + 1
        window = img[max(y0, 0):y1, max(x0, 0):x1, :3].reshape(-1, 3)
        if window.size == 0:
            raise FidelityError(f"patch {k + 1}: centre ({x:.1f}, {y:.1f}) is outside the image")
        out[k] = window.mean(axis=0)
    return out


def delta_e_linear(measured: ArrayLike, expected: ArrayLike) -> FloatArray:
    """CIEDE2000 (n,) between two sets of linear sRGB colours (both to CIELAB D65)."""
    a = xyz_to_lab(linear_srgb_to_xyz(np.asarray(measured, np.float64)))
    b = xyz_to_lab(linear_srgb_to_xyz(np.asarray(expected, np.float64)))
    return np.asarray(delta_e_2000(a, b), np.float64)


def blender_command() -> list[str]:
    """The command that runs ``scenes/blender_render.py``: ``$FIDELITY_BPY_PYTHON`` (a Python
    with bpy), else :data:`BLENDER_VENV` beside the ``fidelity`` package (a checkout's
    ``.venv-blender``, as ``.ci/run`` makes it), ``$FIDELITY_BLENDER`` or ``blender`` on the
    PATH (``blender -b --python``), or this Python when it imports bpy. Raises
    :class:`BlenderUnavailableError`."""
    script = str(resource_dir("scenes") / "blender_render.py")
    py = os.environ.get("FIDELITY_BPY_PYTHON")
    if py:
        return [py, script]
    venv = Path(__file__).resolve().parent.parent.parent / BLENDER_VENV / "bin" / "python"
    if venv.exists():
        return [str(venv), script]
    blender = os.environ.get("FIDELITY_BLENDER") or shutil.which("blender")
    if blender:
        return [blender, "-b", "--factory-startup", "--python", script, "--"]

    if importlib.util.find_spec("bpy") is not None:
        return [sys.executable, script]
    raise BlenderUnavailableError(
        "Blender not found: set FIDELITY_BPY_PYTHON to a Python with the bpy wheel (bpy needs "
        "numpy < 2, so give it its own environment: python3.11 -m venv .venv-blender && "
        ".venv-blender/bin/pip install bpy==5.0.1) or FIDELITY_BLENDER to a blender program")


@record
class BlenderRender:
    """What :func:`render_with_blender` did: the EXR, Blender's JSON line, the wall time."""

    image: Path
    info: dict[str, Any]
    seconds: float


def render_with_blender(scene_file: str | os.PathLike[str], output: str | os.PathLike[str],
                        width: int, height: int, *, samples: int = 4, threads: int = 0,
                        png: str | os.PathLike[str] | None = None,
                        timeout: float = 600.0, png_depth: int = 8, view: str = "Standard",
                        look: str = "None", light_scale: float = 1.0,
                        world: float = 0.0, pixel_filter: str = "BOX",
                        filter_width: float = 1.0,
                        border: tuple[int, int, int, int] | None = None) -> BlenderRender:
    """Render ``scene_file`` (.glb or .usda) with Blender Cycles to the EXR ``output``.

    ``png``: also write the view-transformed image there, ``png_depth`` (8 or 16) bits per
    channel, through the view transform ``view`` (``Standard``, ``AgX``, ``Filmic``) and its
    ``look`` (the EXR is written without them, as Blender does). ``light_scale`` multiplies
    every light's strength (4: +2 EV) and ``world`` is the strength of a grey world
    background (0: black): the settings of the known mistakes
    (``scenes/blender_render.py``). ``pixel_filter`` (``BOX``, ``GAUSSIAN``,
    ``BLACKMAN_HARRIS``) and ``filter_width`` (pixels) are Cycles' pixel filter (default: the
    box of one pixel); ``border`` ``(x0, y0, x1, y1)`` pixels (top left origin, x1 and y1
    exclusive) renders only that part, the EXR cropped to it."""
    cmd = [*blender_command(), str(scene_file), str(output), "--width", str(width),
           "--height", str(height), "--samples", str(samples), "--threads", str(threads)]
    if png is not None:
        cmd += ["--png", str(png), "--png-depth", str(png_depth)]
    if (view, look) != ("Standard", "None"):
        cmd += ["--view", view, "--look", look]
    if light_scale != 1.0:
        cmd += ["--light-scale", repr(float(light_scale))]
    if world:
        cmd += ["--world", repr(float(world))]
    if (pixel_filter, filter_width) != ("BOX", 1.0):
        cmd += ["--filter", pixel_filter, "--filter-width", repr(float(filter_width))]
    if border is not None:
        cmd += ["--border", ",".join(str(int(v)) for v in border)]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env,
                          check=False)
    seconds = time.perf_counter() - t0
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or proc.stdout.strip().splitlines()
                or ["no output"])[-1]
        raise FidelityError(f"{scene_file}: Blender failed (exit {proc.returncode}): {tail}")
    return BlenderRender(Path(output), json.loads(lines[-1]), seconds)


__all__ = ["BLENDER_VENV", "BlenderRender", "BlenderUnavailableError", "blender_command", "delta_e_linear",
           "patch_linear_means", "render_with_blender"]
