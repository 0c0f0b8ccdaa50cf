"""A correction as a 3D LUT that OpenColorIO loads, written and checked by OpenColorIO itself.

A correction maps the simulator's pixel values (``encoding``: sRGB-encoded values in [0, 1], or
scene-linear values) onto corrected values. :func:`bake_cube` samples it on a lattice and has
OpenColorIO's :class:`PyOpenColorIO.Baker` write the Resolve/Adobe ``.cube`` file (the
``resolve_cube`` format that OpenColorIO, Resolve, Nuke, Unreal, Omniverse and Blender load):
an optional 1D shaper (the input -> the lattice's coordinate in [0, 1]) and a 3D LUT.

**The lattice** (:data:`LATTICES`) is spaced evenly either in the sRGB encoding (``encoded``)
or in light (``linear``), whatever the input's encoding; the shaper converts (:func:`shaper`):

- sRGB-encoded input, ``encoded`` lattice: no shaper, the 3D LUT over [0, 1]^3;
- sRGB-encoded input, ``linear`` lattice: the shaper is the sRGB decoding;
- scene-linear input: ``LUT_1D_INPUT_RANGE 0 domain_max`` and the shaper ``v / domain_max``
  (``linear``) or its sRGB encoding (``encoded``; a lattice even in light leaves the shadows
  with one or two nodes).

A model that is affine in light (gains, a matrix) is interpolated exactly by a lattice even in
light (tetrahedral interpolation reproduces affine maps); a model that bends (a tone curve, a
root-polynomial) is sampled more densely in the shadows by the ``encoded`` lattice.

**The output is scene-linear** (the simulator's colourspace and scale, unclipped). The
correction's own output in the sRGB encoding would put the encoding's toe (where an output
channel passes 0.0031 while the others are bright) inside the 3D LUT, where no lattice follows
it: a 20 degree hue correction of sRGB input has 0.27 ΔE00 between a 65^3 cube and the model,
against 0.003 with linear output and a ``linear`` lattice. For sRGB-encoded input the sRGB
encoding is applied after the cube (:func:`output_transform`, OpenColorIO's
``ExponentWithLinearTransform``), which :func:`ocio_config`'s ``sim corrected`` colourspace does,
so that ``sim`` -> ``sim corrected`` keeps the simulator's encoding.

The Baker samples the lattice at the transform's own nodes, so the ``.cube`` holds exactly the
values the correction gives there. :func:`cube_processor` applies a ``.cube`` (and the output
encoding) with OpenColorIO's CPU processor (``FileTransform``, tetrahedral interpolation).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.core.errors import InvalidValueError
from fidelity.core.extras import optional_module

F64 = NDArray[np.float64]

#: Cube sizes tried, smallest first (:func:`fidelity.pipeline.fit` keeps the first within the limit).
CUBE_SIZES: tuple[int, ...] = (33, 65)
#: Samples of the 1D shaper of a scene-linear cube.
SHAPER_SIZE = 4096
#: Name of the extra that installs OpenColorIO.
OCIO_EXTRA = "pip install 'camera-fidelity[fit]'"


def ocio(needed_for: str = "the .cube is written and checked by OpenColorIO",
         extra: str = OCIO_EXTRA) -> Any:
    """The ``PyOpenColorIO`` module, or one clear error: what needs it (``needed_for``), and
    the ``extra`` that installs it."""
    return optional_module("PyOpenColorIO", needed_for, extra)


#: How the 3D lattice is spaced (module docstring).
LATTICES: tuple[str, ...] = ("encoded", "linear")


def _check_lattice(encoding: str, lattice: str) -> None:
    if encoding not in ("srgb", "linear"):
        raise InvalidValueError(f"encoding {encoding!r}: expected srgb or linear")
    if lattice not in LATTICES:
        raise InvalidValueError(f"lattice {lattice!r}: expected one of {', '.join(LATTICES)}")


def _srgb(direction: str) -> Any:
    """OpenColorIO's IEC 61966-2-1 sRGB curve: ``decode`` (encoded -> linear) or ``encode``."""
    oc = ocio()
    return oc.ExponentWithLinearTransform(
        gamma=[2.4, 2.4, 2.4, 1.0], offset=[0.055, 0.055, 0.055, 0.0],
        direction=oc.TRANSFORM_DIR_FORWARD if direction == "decode" else oc.TRANSFORM_DIR_INVERSE)


def shaper(encoding: str, lattice: str, domain_max: float) -> Any:
    """The OpenColorIO transform from the input pixel values to the lattice's coordinate in
    [0, 1] (module docstring), or None where they are the same (sRGB input, ``encoded``)."""
    _check_lattice(encoding, lattice)
    oc = ocio()
    if encoding == "srgb":
        return None if lattice == "encoded" else _srgb("decode")
    s = 1.0 / domain_max
    scale = oc.MatrixTransform(matrix=[s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0, 0, 0, 0, 1])
    return scale if lattice == "linear" else oc.GroupTransform([scale, _srgb("encode")])


def output_transform(encoding: str) -> Any:
    """What follows the cube so that its scene-linear output is in the input's ``encoding``:
    the sRGB encoding, or None for scene-linear input."""
    return _srgb("encode") if encoding == "srgb" else None


def lattice_inputs(size: int, encoding: str, domain_max: float,
                   lattice: str = "encoded") -> F64:
    """The pixel values at the 3D lattice's nodes, ``(size, size, size, 3)`` indexed
    ``[r, g, b]``: the shaper's inverse of the evenly spaced nodes in [0, 1]."""
    _check_lattice(encoding, lattice)
    t = np.linspace(0.0, 1.0, size)
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1)
    if encoding == "srgb":
        return grid if lattice == "encoded" else np.asarray(delinearize_srgb(grid), np.float64)
    return domain_max * (grid if lattice == "linear"
                         else np.asarray(linearize_srgb(grid), np.float64))


def _config(correction: Callable[[F64], F64], size: int, encoding: str,
            domain_max: float, lattice: str) -> Any:
    oc = ocio()
    lut = oc.Lut3DTransform(gridSize=size)
    values = np.asarray(correction(lattice_inputs(size, encoding, domain_max, lattice)),
                        np.float64)
    if not np.all(np.isfinite(values)):
        raise InvalidValueError("the correction gives NaN or Inf on the LUT's lattice")
    lut.setData(np.ascontiguousarray(values, np.float32).ravel())
    lut.setInterpolation(oc.INTERP_TETRAHEDRAL)
    config = oc.Config.CreateRaw()
    config.addColorSpace(oc.ColorSpace(name="sim"))
    target = oc.ColorSpace(name="sim corrected")
    shape = shaper(encoding, lattice, domain_max)
    if shape is None:
        target.setTransform(lut, oc.COLORSPACE_DIR_FROM_REFERENCE)
    else:
        space = oc.ColorSpace(name="sim shaper")
        space.setTransform(shape, oc.COLORSPACE_DIR_FROM_REFERENCE)
        config.addColorSpace(space)
        target.setTransform(oc.GroupTransform([shaper(encoding, lattice, domain_max), lut]),
                            oc.COLORSPACE_DIR_FROM_REFERENCE)
    config.addColorSpace(target)
    return config


def bake_cube(correction: Callable[[F64], F64], size: int, encoding: str,
              domain_max: float = 1.0, comments: Sequence[str] = (),
              lattice: str = "encoded") -> str:
    """The ``.cube`` text of ``correction`` (pixel values ``(..., 3)`` in ``encoding`` ->
    corrected scene-linear values), baked by OpenColorIO's Baker (module docstring) with a
    ``size``^3 ``lattice``; ``comments`` become ``#`` lines at the top (the Resolve format's
    comment lines)."""
    _check_lattice(encoding, lattice)
    if not (np.isfinite(domain_max) and domain_max > 0):
        raise InvalidValueError(f"LUT domain maximum {domain_max!r}: must be a positive number")
    oc = ocio()
    baker = oc.Baker()
    baker.setConfig(_config(correction, size, encoding, domain_max, lattice))
    baker.setFormat("resolve_cube")
    baker.setInputSpace("sim")
    baker.setTargetSpace("sim corrected")
    if shaper(encoding, lattice, domain_max) is not None:
        baker.setShaperSpace("sim shaper")
        baker.setShaperSize(SHAPER_SIZE)
    baker.setCubeSize(size)
    text = str(baker.bake())
    head = "".join(f"# {' '.join(c.split())}\n" for c in comments)
    return head + text


def correction_transform(cube: str, encoding: str) -> Any:
    """The ``FileTransform`` of the ``.cube`` named ``cube`` (tetrahedral interpolation),
    followed by :func:`output_transform`: the simulator's pixels -> corrected pixels in the
    same encoding."""
    oc = ocio()
    ft = oc.FileTransform(src=cube, interpolation=oc.INTERP_TETRAHEDRAL)
    post = output_transform(encoding)
    return ft if post is None else oc.GroupTransform([ft, post])


def cube_processor(path: str | os.PathLike[str], encoding: str = "linear", *,
                   reload: bool = True) -> Any:
    """OpenColorIO's CPU processor of the ``.cube`` at ``path`` and the output encoding of
    ``encoding`` input (:func:`correction_transform`). ``reload``: read the file again
    (OpenColorIO caches files by path; ``False`` only where the file is known unchanged since
    it was last read)."""
    oc = ocio()
    if reload:
        oc.ClearAllCaches()  # a rewritten cube must be read again
    transform = correction_transform(str(Path(path).resolve()), encoding)
    return oc.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()


def apply_processor(processor: Any, pixels: NDArray[Any]) -> NDArray[np.float32]:
    """``pixels`` ``(..., 3)`` through an OpenColorIO CPU processor (as a new float32 array:
    ``pixels`` is left as it was)."""
    a = np.array(pixels, np.float32, order="C", copy=True).reshape(-1, 3)
    processor.applyRGB(a)
    return a.reshape(np.shape(pixels))


def ocio_config(cube: str | os.PathLike[str], description: str = "",
                encoding: str = "linear") -> str:
    """An OpenColorIO config (text) with the colourspaces ``sim`` and ``sim corrected``, the
    latter :func:`correction_transform` of ``cube`` (its file name, found next to the config
    through the search path ``.``) for ``encoding`` input, serialised by OpenColorIO."""
    oc = ocio()
    config = oc.Config.CreateRaw()
    config.setSearchPath(".")
    config.setDescription(" ".join(description.split()))
    config.addColorSpace(oc.ColorSpace(name="sim"))
    corrected = oc.ColorSpace(name="sim corrected")
    corrected.setTransform(correction_transform(Path(cube).name, encoding),
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


__all__ = ["CUBE_SIZES", "LATTICES", "OCIO_EXTRA", "SHAPER_SIZE", "apply_processor",
           "bake_cube", "config_processor", "correction_transform", "cube_processor",
           "lattice_inputs", "ocio", "ocio_config", "output_transform", "shaper"]
