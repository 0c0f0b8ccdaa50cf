"""Pixels in an OpenColorIO colourspace, converted by OpenColorIO to what the audit measures.

A render or a camera's footage is often described by the colourspace of a studio's OpenColorIO
config (``ACEScct``, ``ARRI LogC4``, ``Linear Rec.2020``, ``Display P3 - Display``...) rather
than by primaries and the sRGB curve (``--colourspace``, ``--encoding``). With
``--ocio-colourspace NAME`` the pixels are converted by OpenColorIO from that colourspace of the
config (``--ocio-config``; default ``$OCIO``, else OpenColorIO's built-in default config
``ocio://default``) to one of the built-in default config, through the two configs' interchange
roles (:meth:`PyOpenColorIO.Config.GetProcessorFromConfigs`):

- a scene-referred colourspace -> ``Linear Rec.709 (sRGB)``, measured as linear (scene light;
  exposure fitted on the neutral patches unless ``--exposure`` says otherwise);
- a display-referred colourspace -> ``sRGB - Display``, measured as sRGB-encoded.

OpenColorIO applies each config's own chromatic adaptation (the ACES configs' Bradford between
the ACES white and D65), so the audit sees the values a user's pipeline would give. A data
colourspace (``isData``: normals, masks) holds no colours and is refused.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from fidelity.core.errors import InvalidValueError
from fidelity.core.extras import optional_module
from fidelity.core.record import record

#: The config used when neither ``--ocio-config`` nor ``$OCIO`` names one.
DEFAULT_CONFIG = "ocio://default"
#: Colourspaces of :data:`DEFAULT_CONFIG` the pixels are converted to, by reference space.
SCENE_TARGET = "Linear Rec.709 (sRGB)"
DISPLAY_TARGET = "sRGB - Display"
#: What installs OpenColorIO.
OCIO_EXTRA = "pip install 'camera-fidelity[ocio]'"


@record
class OcioConversion:
    """How an image's pixels were converted: the source ``colourspace`` of the ``config``
    (its name, where it came from, and OpenColorIO's cache ID: a digest of its content), the
    colourspace of the built-in default config they were converted to, the ``encoding`` the
    result is measured in (``linear`` or ``srgb``) and OpenColorIO's version."""

    colourspace: str
    config: str
    config_name: str
    config_id: str
    target: str
    encoding: str
    version: str

    def to_json(self) -> dict[str, str]:
        """The fields as a JSON object (keys in field order)."""
        return {"colourspace": self.colourspace, "config": self.config,
                "config_name": self.config_name, "config_id": self.config_id,
                "target": self.target, "encoding": self.encoding, "version": self.version}


def _module() -> Any:
    return optional_module("PyOpenColorIO", "--ocio-colourspace converts with OpenColorIO",
                           OCIO_EXTRA)


def config_source(config: str | os.PathLike[str] | None) -> str:
    """Where the config comes from: ``config``, else ``$OCIO``, else :data:`DEFAULT_CONFIG`."""
    if config is not None and str(config):
        return str(config)
    return os.environ.get("OCIO") or DEFAULT_CONFIG


def load_config(config: str | os.PathLike[str] | None) -> tuple[Any, str]:
    """The OpenColorIO config (:func:`config_source`) and where it came from; a config that
    cannot be read is one error naming it."""
    ocio = _module()
    where = config_source(config)
    if not where.startswith("ocio://") and not os.path.isfile(where):
        raise InvalidValueError(f"--ocio-config {where}: no such config file")
    try:
        return ocio.Config.CreateFromFile(where), where
    except Exception as exc:  # OpenColorIO raises its own Exception for every failure
        raise InvalidValueError(f"--ocio-config {where}: OpenColorIO cannot read it: "
                                f"{' '.join(str(exc).split())}") from None


def convert(pixels: np.ndarray, colourspace: str,
            config: str | os.PathLike[str] | None = None, *, copy: bool = True
            ) -> tuple[np.ndarray, OcioConversion]:
    """Convert ``(H, W, 3)`` float values in ``colourspace`` of ``config`` (module docstring).

    Parameters
    ----------
    pixels
        ``(H, W, 3)`` float values (NaN and Inf pass through as OpenColorIO leaves them).
    colourspace
        A colourspace name (or alias) of the config.
    config
        A config file or an ``ocio://`` URI; None: ``$OCIO``, else :data:`DEFAULT_CONFIG`.
    copy
        False: convert ``pixels`` in place when they are a writeable C-contiguous float32
        array (the caller's own: 12 bytes a pixel spared); a new array otherwise.

    Returns
    -------
    The converted ``(H, W, 3)`` float32 values and the :class:`OcioConversion` that says what
    was done.
    """
    ocio = _module()
    arr = np.asarray(pixels)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidValueError(f"image must be (H, W, 3), got shape {arr.shape}")
    src, where = load_config(config)
    space = src.getColorSpace(colourspace)
    if space is None:
        known = ", ".join(sorted(c.getName() for c in src.getColorSpaces()))
        raise InvalidValueError(f"--ocio-colourspace {colourspace}: not a colourspace of the "
                                f"OpenColorIO config {where}; its colourspaces: {known}")
    if space.isData():
        raise InvalidValueError(f"--ocio-colourspace {colourspace}: a data colourspace of "
                                f"{where} (its values are not colours)")
    scene = space.getReferenceSpaceType() == ocio.REFERENCE_SPACE_SCENE
    target = SCENE_TARGET if scene else DISPLAY_TARGET
    builtin = ocio.Config.CreateFromFile(DEFAULT_CONFIG)
    try:
        processor = ocio.Config.GetProcessorFromConfigs(src, space.getName(), builtin, target)
    except Exception as exc:
        raise InvalidValueError(
            f"--ocio-colourspace {colourspace}: OpenColorIO cannot convert it from {where} to "
            f"{target} of its built-in config: {' '.join(str(exc).split())}") from None
    out = np.ascontiguousarray(arr, dtype=np.float32)
    if out is arr and (copy or not out.flags.writeable):
        out = out.copy()
    processor.getDefaultCPUProcessor().applyRGB(out)
    return out, OcioConversion(space.getName(), where, src.getName() or "", src.getCacheID(),
                               target, "linear" if scene else "srgb", ocio.__version__)


__all__ = ["DEFAULT_CONFIG", "DISPLAY_TARGET", "OCIO_EXTRA", "SCENE_TARGET", "OcioConversion",
           "config_source", "convert", "load_config"]
