"""A correction as a 3D LUT that ffmpeg, OpenImageIO and OpenColorIO apply alike, written and
checked by OpenColorIO itself.

A correction maps the simulator's pixel values (``encoding``: sRGB-encoded values in [0, 1], or
scene-linear values in [0, ``domain_max``]) onto corrected values. :func:`bake_cube` samples it
on a lattice and has OpenColorIO's :class:`PyOpenColorIO.Baker` write the ``.cube`` file: a
3D LUT alone, with no 1D shaper, read the same way by ffmpeg's ``lut3d`` filter, OpenImageIO's
``oiiotool --ociofiletransform``, OpenColorIO's ``FileTransform``, Resolve and Nuke.

**No shaper.** A ``.cube`` holding a 1D shaper and a 3D LUT (``LUT_1D_SIZE`` with
``LUT_3D_SIZE``) is misread by ffmpeg 5.1's ``lut3d``, which takes the shaper's rows for the 3D
LUT's (issue 57: 34.9 ΔE00 against oiiotool's 26.1). The lattice is therefore even in the
input's own values: the sRGB-encoded values [0, 1]^3 for an sRGB SIM; for a scene-linear SIM
[0, ``domain_max``]^3, declared by the Adobe keywords ``DOMAIN_MIN 0 0 0`` and ``DOMAIN_MAX m m
m`` right after ``LUT_3D_SIZE`` (where ffmpeg reads them; OpenColorIO reads them anywhere in the
header), so that values above 1 are corrected, not clamped.

**The output** (:data:`CUBE_OUTPUTS`) is ``encoded`` (the IEC 61966-2-1 sRGB encoding of the
corrected scene-linear value, continued below 0 by its linear segment and above 1 by its power
segment, unclipped) or ``linear`` (the corrected scene-linear value: the simulator's colourspace
and scale, unclipped). :func:`default_output` is the input's own encoding, as every one of
those tools applies a cube: sRGB in, sRGB out; linear in, linear out.

**The lattice size** is the smallest of :data:`CUBE_SIZES` whose check passes
(:func:`fidelity.pipeline.fit.check_cube`; 129 is the largest lattice OpenColorIO reads). A
model that is affine in light (gains, a matrix) is interpolated exactly by a lattice even in
light (tetrahedral interpolation reproduces affine maps); on sRGB-encoded input with
sRGB-encoded output the encoding's toe, where an output channel passes 0.0031 while the others
are bright, falls between the nodes (a 20 degree hue correction at 65^3: 0.27 ΔE00 at the
lattice's most saturated colours, 0.044 at its 99th percentile).

The Baker samples the lattice at the transform's own nodes, so the ``.cube`` holds exactly the
values the correction gives there (to the six decimals of the format). :func:`cube_processor`
applies a ``.cube`` with OpenColorIO's CPU processor (``FileTransform``, tetrahedral
interpolation).
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

#: Cube sizes tried, smallest first (:func:`fidelity.pipeline.fit.fit_and_verify` keeps the
#: first whose check passes); 129 is the largest 3D LUT OpenColorIO reads.
CUBE_SIZES: tuple[int, ...] = (33, 65, 129)
#: Name of the extra that installs OpenColorIO.
OCIO_EXTRA = "pip install 'camera-fidelity[fit]'"
#: The output conventions of a ``.cube`` (module docstring).
CUBE_OUTPUTS: tuple[str, ...] = ("encoded", "linear")
#: How the points of :func:`lattice_inputs` may be spaced: evenly in the sRGB encoding
#: (``encoded``) or in light (``linear``).
LATTICES: tuple[str, ...] = ("encoded", "linear")


def ocio(needed_for: str = "the .cube is written and checked by OpenColorIO",
         extra: str = OCIO_EXTRA) -> Any:
    """The ``PyOpenColorIO`` module, or one clear error: what needs it (``needed_for``), and
    the ``extra`` that installs it."""
    return optional_module("PyOpenColorIO", needed_for, extra)


def _check_encoding(encoding: str) -> None:
    if encoding not in ("srgb", "linear"):
        raise InvalidValueError(f"encoding {encoding!r}: expected srgb or linear")


def check_output(output: str) -> str:
    """``output`` if it is one of :data:`CUBE_OUTPUTS`, else one clear error."""
    if output not in CUBE_OUTPUTS:
        raise InvalidValueError(f"cube output {output!r}: expected one of "
                                f"{', '.join(CUBE_OUTPUTS)}")
    return output


def default_output(encoding: str) -> str:
    """The output convention of a ``.cube`` for input in ``encoding`` unless told: the
    input's own (``encoded`` for ``srgb``, ``linear`` for ``linear``)."""
    _check_encoding(encoding)
    return "encoded" if encoding == "srgb" else "linear"


def output_values(linear: F64, output: str) -> F64:
    """Corrected scene-linear values ``(..., 3)`` as a ``.cube`` with ``output`` holds them:
    sRGB-encoded (unclipped, module docstring) or as they are."""
    check_output(output)
    return (np.asarray(delinearize_srgb(linear), np.float64) if output == "encoded"
            else np.asarray(linear, np.float64))


def output_linear(values: NDArray[Any], output: str) -> F64:
    """Inverse of :func:`output_values`: the scene-linear values of a ``.cube``'s output."""
    check_output(output)
    v = np.asarray(values, np.float64)
    return np.asarray(linearize_srgb(v), np.float64) if output == "encoded" else v


def input_domain(encoding: str, domain_max: float) -> float:
    """The largest input value of each channel a ``.cube`` covers: 1 for sRGB-encoded input,
    ``domain_max`` for scene-linear input."""
    _check_encoding(encoding)
    return 1.0 if encoding == "srgb" else float(domain_max)


def lattice_inputs(size: int, encoding: str, domain_max: float,
                   lattice: str = "linear") -> F64:
    """``size``^3 pixel values ``(size, size, size, 3)`` indexed ``[r, g, b]`` spanning a
    ``.cube``'s input range (:func:`input_domain`), evenly in the input's own values
    (``lattice="linear"``: a ``.cube``'s nodes) or, for scene-linear input, evenly in the
    sRGB encoding of ``v / domain_max`` (``"encoded"``: denser in the shadows, the points a
    cube is checked on)."""
    _check_encoding(encoding)
    if lattice not in LATTICES:
        raise InvalidValueError(f"lattice {lattice!r}: expected one of {', '.join(LATTICES)}")
    t = np.linspace(0.0, 1.0, size)
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1)
    if encoding == "srgb":
        return grid
    return domain_max * (grid if lattice == "linear"
                         else np.asarray(linearize_srgb(grid), np.float64))


def _domain_lines(text: str, top: float) -> str:
    """``text`` (the Baker's ``.cube``) with ``DOMAIN_MIN``/``DOMAIN_MAX`` right after its
    ``LUT_3D_SIZE`` line (where ffmpeg's parser reads them), unless the domain is [0, 1]."""
    if top == 1.0:
        return text
    head, rest = text.split("\n", 1)
    if not head.startswith("LUT_3D_SIZE"):
        raise InvalidValueError(f"unexpected .cube from OpenColorIO's Baker: {head!r}")
    m = f"{top:.9g}"
    return f"{head}\nDOMAIN_MIN 0 0 0\nDOMAIN_MAX {m} {m} {m}\n{rest}"


def bake_cube(correction: Callable[[F64], F64], size: int, encoding: str,
              domain_max: float = 1.0, comments: Sequence[str] = (), title: str = "") -> str:
    """The ``.cube`` text of ``correction`` (pixel values ``(..., 3)`` in ``encoding`` -> the
    values the cube holds, :func:`output_values`), baked by OpenColorIO's Baker (module
    docstring) on a ``size``^3 lattice even in the input's values over [0,
    :func:`input_domain`]; ``title`` becomes the ``TITLE`` line and ``comments`` ``#`` lines
    at the top."""
    _check_encoding(encoding)
    if not (np.isfinite(domain_max) and domain_max > 0):
        raise InvalidValueError(f"LUT domain maximum {domain_max!r}: must be a positive number")
    top = input_domain(encoding, domain_max)
    oc = ocio()
    values = np.asarray(correction(lattice_inputs(size, encoding, top)), np.float64)
    if not np.all(np.isfinite(values)):
        raise InvalidValueError("the correction gives NaN or Inf on the LUT's lattice")
    lut = oc.Lut3DTransform(gridSize=size)
    lut.setData(np.ascontiguousarray(values, np.float32).ravel())
    lut.setInterpolation(oc.INTERP_TETRAHEDRAL)
    # the Baker samples [0, 1]^3 at the lattice's nodes: the LUT itself, node for node
    config = oc.Config.CreateRaw()
    config.addColorSpace(oc.ColorSpace(name="sim"))
    target = oc.ColorSpace(name="sim corrected")
    target.setTransform(lut, oc.COLORSPACE_DIR_FROM_REFERENCE)
    config.addColorSpace(target)
    baker = oc.Baker()
    baker.setConfig(config)
    baker.setFormat("resolve_cube")
    baker.setInputSpace("sim")
    baker.setTargetSpace("sim corrected")
    baker.setCubeSize(size)
    text = _domain_lines(str(baker.bake()), top)
    head = "".join(f"# {' '.join(c.split())}\n" for c in comments)
    if title:
        head += f"TITLE \"{' '.join(title.replace(chr(34), chr(39)).split())}\"\n"
    return head + text


def correction_transform(cube: str) -> Any:
    """The ``FileTransform`` of the ``.cube`` named ``cube`` (tetrahedral interpolation):
    the simulator's pixels -> the cube's output."""
    oc = ocio()
    return oc.FileTransform(src=cube, interpolation=oc.INTERP_TETRAHEDRAL)


def cube_processor(path: str | os.PathLike[str], *, reload: bool = True) -> Any:
    """OpenColorIO's CPU processor of the ``.cube`` at ``path``
    (:func:`correction_transform`). ``reload``: read the file again (OpenColorIO caches files
    by path; ``False`` only where the file is known unchanged since it was last read)."""
    oc = ocio()
    if reload:
        oc.ClearAllCaches()  # a rewritten cube must be read again
    transform = correction_transform(str(Path(path).resolve()))
    return oc.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()


def apply_processor(processor: Any, pixels: NDArray[Any]) -> NDArray[np.float32]:
    """``pixels`` ``(..., 3)`` through an OpenColorIO CPU processor (as a new float32 array:
    ``pixels`` is left as it was)."""
    a = np.array(pixels, np.float32, order="C", copy=True).reshape(-1, 3)
    processor.applyRGB(a)
    return a.reshape(np.shape(pixels))


def ocio_config(cube: str | os.PathLike[str], description: str = "") -> str:
    """An OpenColorIO config (text) with the colourspaces ``sim`` and ``sim corrected``, the
    latter :func:`correction_transform` of ``cube`` (its file name, found next to the config
    through the search path ``.``), serialised by OpenColorIO."""
    oc = ocio()
    config = oc.Config.CreateRaw()
    config.setSearchPath(".")
    config.setDescription(" ".join(description.split()))
    config.addColorSpace(oc.ColorSpace(name="sim"))
    corrected = oc.ColorSpace(name="sim corrected")
    corrected.setTransform(correction_transform(Path(cube).name),
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


__all__ = ["CUBE_OUTPUTS", "CUBE_SIZES", "LATTICES", "OCIO_EXTRA", "apply_processor",
           "bake_cube", "check_output", "config_processor", "correction_transform",
           "cube_processor", "default_output", "input_domain", "lattice_inputs", "ocio",
           "ocio_config", "output_linear", "output_values"]
