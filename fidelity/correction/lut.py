"""A correction as a 3D LUT that OpenColorIO loads, written and checked by OpenColorIO itself.

A correction maps the simulator's pixel values (``encoding``: sRGB-encoded values in [0, 1], or
scene-linear values) onto corrected pixel values in the same encoding. :func:`bake_cube` samples
it on a lattice and has OpenColorIO's :class:`PyOpenColorIO.Baker` write the Resolve/Adobe
``.cube`` file (the ``resolve_cube`` format that OpenColorIO, Resolve, Nuke, Unreal, Omniverse
and Blender load):

- sRGB-encoded input: a 3D LUT over [0, 1]^3;
- scene-linear input: a 1D shaper (``LUT_1D_INPUT_RANGE 0 domain_max``; linear ->
  the sRGB encoding of ``v / domain_max``, OpenColorIO's ``ExponentWithLinearTransform`` with
  the IEC 61966-2-1 parameters) and a 3D LUT on the shaper's output, so that the lattice is
  spaced evenly in lightness rather than in light (a linear lattice leaves the shadows with
  one or two nodes).

The Baker samples the lattice at the transform's own nodes, so the ``.cube`` holds exactly the
values the correction gives there. :func:`cube_processor` applies a ``.cube`` with
OpenColorIO's CPU processor (``FileTransform``, tetrahedral interpolation); :func:`ocio_config`
writes a small OpenColorIO config whose colourspace ``sim corrected`` is the ``FileTransform``
of the cube from ``sim``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.errors import InvalidValueError

F64 = NDArray[np.float64]

#: Cube sizes tried, smallest first (:func:`fidelity.fit` keeps the first within the limit).
CUBE_SIZES: tuple[int, ...] = (33, 65)
#: Samples of the 1D shaper of a scene-linear cube.
SHAPER_SIZE = 4096
#: Name of the extra that installs OpenColorIO.
OCIO_EXTRA = "pip install 'camera-fidelity[fit]'"


def ocio() -> Any:
    """The ``PyOpenColorIO`` module, or one clear error naming the extra that installs it."""
    try:
        import PyOpenColorIO
    except ImportError:
        raise InvalidValueError(f"the .cube is written and checked by OpenColorIO, which is not "
                                f"installed: {OCIO_EXTRA}") from None
    return PyOpenColorIO


def _shaper(domain_max: float) -> Any:
    oc = ocio()
    s = 1.0 / domain_max
    return oc.GroupTransform([
        oc.MatrixTransform(matrix=[s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0, 0, 0, 0, 1]),
        oc.ExponentWithLinearTransform(gamma=[2.4, 2.4, 2.4, 1.0],
                                       offset=[0.055, 0.055, 0.055, 0.0],
                                       direction=oc.TRANSFORM_DIR_INVERSE)])


def lattice_inputs(size: int, encoding: str, domain_max: float) -> F64:
    """The pixel values at the 3D lattice's nodes, ``(size, size, size, 3)`` indexed
    ``[r, g, b]``: the nodes themselves for sRGB-encoded input, ``domain_max`` times the
    sRGB-decoded nodes for scene-linear input (the shaper's inverse)."""
    from fidelity.colour.colorimetry import linearize_srgb

    t = np.linspace(0.0, 1.0, size)
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1)
    if encoding == "srgb":
        return grid
    return domain_max * np.asarray(linearize_srgb(grid), np.float64)


def _config(correction: Callable[[F64], F64], size: int, encoding: str,
            domain_max: float) -> Any:
    oc = ocio()
    lut = oc.Lut3DTransform(gridSize=size)
    values = np.asarray(correction(lattice_inputs(size, encoding, domain_max)), np.float64)
    if not np.all(np.isfinite(values)):
        raise InvalidValueError("the correction gives NaN or Inf on the LUT's lattice")
    lut.setData(np.ascontiguousarray(values, np.float32).ravel())
    lut.setInterpolation(oc.INTERP_TETRAHEDRAL)
    config = oc.Config.CreateRaw()
    sim = oc.ColorSpace(name="sim")
    config.addColorSpace(sim)
    target = oc.ColorSpace(name="sim corrected")
    if encoding == "srgb":
        target.setTransform(lut, oc.COLORSPACE_DIR_FROM_REFERENCE)
    else:
        shaper = oc.ColorSpace(name="sim shaper")
        shaper.setTransform(_shaper(domain_max), oc.COLORSPACE_DIR_FROM_REFERENCE)
        config.addColorSpace(shaper)
        target.setTransform(oc.GroupTransform([_shaper(domain_max), lut]),
                            oc.COLORSPACE_DIR_FROM_REFERENCE)
    config.addColorSpace(target)
    return config


def bake_cube(correction: Callable[[F64], F64], size: int, encoding: str,
              domain_max: float = 1.0, comments: Sequence[str] = ()) -> str:
    """The ``.cube`` text of ``correction`` (pixel values ``(..., 3)`` -> corrected values),
    baked by OpenColorIO's Baker (module docstring) with a ``size``^3 lattice; ``comments``
    become ``#`` lines at the top (the Resolve format's comment lines)."""
    if encoding not in ("srgb", "linear"):
        raise InvalidValueError(f"encoding {encoding!r}: expected srgb or linear")
    if not (np.isfinite(domain_max) and domain_max > 0):
        raise InvalidValueError(f"LUT domain maximum {domain_max!r}: must be a positive number")
    oc = ocio()
    baker = oc.Baker()
    baker.setConfig(_config(correction, size, encoding, domain_max))
    baker.setFormat("resolve_cube")
    baker.setInputSpace("sim")
    baker.setTargetSpace("sim corrected")
    if encoding == "linear":
        baker.setShaperSpace("sim shaper")
        baker.setShaperSize(SHAPER_SIZE)
    baker.setCubeSize(size)
    text = str(baker.bake())
    head = "".join(f"# {' '.join(c.split())}\n" for c in comments)
    return head + text


def cube_processor(path: str | os.PathLike[str]) -> Any:
    """OpenColorIO's CPU processor of the ``.cube`` at ``path`` (a ``FileTransform``,
    tetrahedral interpolation)."""
    oc = ocio()
    oc.ClearAllCaches()  # OpenColorIO caches files by path: a rewritten cube must be read again
    ft = oc.FileTransform(src=str(Path(path).resolve()), interpolation=oc.INTERP_TETRAHEDRAL)
    return oc.Config.CreateRaw().getProcessor(ft).getDefaultCPUProcessor()


def apply_processor(processor: Any, pixels: NDArray[Any]) -> NDArray[np.float32]:
    """``pixels`` ``(..., 3)`` through an OpenColorIO CPU processor (as float32)."""
    a = np.ascontiguousarray(np.asarray(pixels, np.float32).reshape(-1, 3))
    processor.applyRGB(a)
    return a.reshape(np.shape(pixels))


def ocio_config(cube: str | os.PathLike[str], description: str = "") -> str:
    """An OpenColorIO config (text) with the colourspaces ``sim`` and ``sim corrected``, the
    latter the ``FileTransform`` of ``cube`` (its file name, found next to the config through
    the search path ``.``), serialised by OpenColorIO."""
    oc = ocio()
    config = oc.Config.CreateRaw()
    config.setSearchPath(".")
    config.setDescription(" ".join(description.split()))
    config.addColorSpace(oc.ColorSpace(name="sim"))
    corrected = oc.ColorSpace(name="sim corrected")
    corrected.setTransform(oc.FileTransform(src=Path(cube).name,
                                            interpolation=oc.INTERP_TETRAHEDRAL),
                           oc.COLORSPACE_DIR_FROM_REFERENCE)
    config.addColorSpace(corrected)
    config.setRole("scene_linear", "sim")
    config.validate()
    return str(config.serialize())


def config_processor(path: str | os.PathLike[str]) -> Any:
    """The ``sim`` -> ``sim corrected`` CPU processor of a config written by
    :func:`ocio_config`."""
    oc = ocio()
    oc.ClearAllCaches()
    config = oc.Config.CreateFromFile(str(path))
    return config.getProcessor("sim", "sim corrected").getDefaultCPUProcessor()


__all__ = ["CUBE_SIZES", "OCIO_EXTRA", "SHAPER_SIZE", "apply_processor", "bake_cube",
           "config_processor", "cube_processor", "lattice_inputs", "ocio", "ocio_config"]
