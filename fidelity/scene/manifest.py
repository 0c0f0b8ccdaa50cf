"""Read back what a render of an exported chart scene is judged with: its manifest.

``fidelity scene`` writes ``manifest.json`` beside the scene (:func:`fidelity.scene.export.
manifest`). A gate or audit of the render takes it with ``--manifest``: the patch corners in
the camera's image, the exposure correction that maps the scene's white level to the
reference (``expected_exposure.gate_exposure_ev``), the reference and its illuminant
(:class:`ChartManifest`). With a manifest the exposure is fixed at the expected one and judged
(:mod:`fidelity.prediction.exposure`), not normalised away.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from fidelity.core.errors import InputFileError
from fidelity.core.fileio import display_path
from fidelity.core.record import record
from fidelity.measure.chartsharpness import EdgeTargetCorners

__all__ = ["MANIFEST_KIND", "ChartManifest", "read_manifest"]

#: The ``kind`` of a chart scene's manifest.
MANIFEST_KIND = "fidelity chart scene"


@record
class ChartManifest:
    """What a chart scene's manifest says a render is judged with.

    Attributes
    ----------
    path
        The manifest file.
    corners
        Image centres of the dark skin, bluish green, black and white patches, as the
        ``--corners`` text ``"X1,Y1,...,X4,Y4"`` (pixels; pixel (row i, column j) at x=j,
        y=i).
    exposure_ev
        The exposure correction, in EV, that maps the scene's white level to the
        reference's (``-log2(white_level)``; 0 for a white level of 1).
    white_level
        The linear value a perfect white reflector renders at.
    reference
        The reference chart (``scene``, ``safecolor`` or a chart JSON).
    illuminant
        The scene's illuminant.
    edge_target
        The slanted-edge target's corners in the camera's image (``edge_target``'s
        ``square_corners_px`` and ``field_corners_px``); None: the manifest has none (one
        written before the scenes carried it) or the target lies outside the image.
    """

    path: Path
    corners: str
    exposure_ev: float
    white_level: float
    reference: str
    illuminant: str
    edge_target: EdgeTargetCorners | None = None


def _edge_target(doc: dict[str, Any], path: Path) -> EdgeTargetCorners | None:
    """The manifest's ``edge_target`` corners; None where it has none or it is outside."""
    target = doc.get("edge_target")
    if target is None:
        return None
    bad = InputFileError(f"{display_path(path)}: not a chart scene manifest: edge_target "
                         "needs square_corners_px and field_corners_px, 4 [x, y] each")
    if not isinstance(target, dict):
        raise bad
    if target.get("in_image") is False:
        return None
    corners = []
    for key in ("square_corners_px", "field_corners_px"):
        pts = target.get(key)
        if (not isinstance(pts, list) or len(pts) != 4
                or not all(isinstance(p, list) and len(p) == 2
                           and all(isinstance(v, int | float) and not isinstance(v, bool)
                                   and math.isfinite(v) for v in p) for p in pts)):
            raise bad
        corners.append(tuple((float(p[0]), float(p[1])) for p in pts))
    return EdgeTargetCorners(corners[0], corners[1], f"manifest {display_path(path)}")


def _number(doc: dict[str, Any], path: Path, *keys: str) -> float:
    value: Any = doc
    for key in keys:
        value = value.get(key) if isinstance(value, dict) else None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputFileError(f"{display_path(path)}: not a chart scene manifest: "
                             f"{'.'.join(keys)} is not a finite number")
    return float(value)


def _text(doc: dict[str, Any], path: Path, key: str) -> str:
    value = doc.get(key)
    if not isinstance(value, str) or not value.strip():
        raise InputFileError(f"{display_path(path)}: not a chart scene manifest: {key} is "
                             f"missing or not text")
    return value


def read_manifest(path: str | Path) -> ChartManifest:
    """Read a chart scene's ``manifest.json``.

    Parameters
    ----------
    path
        The manifest ``fidelity scene`` wrote, or the folder holding it.

    Returns
    -------
    ChartManifest
        Its corners, expected exposure, white level, reference, illuminant and the edge
        target's corners.

    Raises
    ------
    InputFileError
        A missing or unreadable file, not JSON, not a chart scene manifest (its ``kind``), or
        a field missing or of the wrong type; the message names the file and the field.
        Exit code 2.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "manifest.json"
    try:
        doc = json.loads(p.read_bytes())
    except FileNotFoundError:
        raise InputFileError(f"{display_path(p)}: no such manifest") from None
    except OSError as exc:
        raise InputFileError(f"{display_path(p)}: cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise InputFileError(f"{display_path(p)}: not JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("kind") != MANIFEST_KIND:
        raise InputFileError(f"{display_path(p)}: not a chart scene manifest (kind "
                             f"{MANIFEST_KIND!r}, written by fidelity scene)")
    white = _number(doc, p, "white_level")
    if white <= 0:
        raise InputFileError(f"{display_path(p)}: white_level {white:g} must be > 0")
    return ChartManifest(
        path=p, corners=_text(doc, p, "corners"),
        exposure_ev=_number(doc, p, "expected_exposure", "gate_exposure_ev"),
        white_level=white, reference=_text(doc, p, "reference"),
        illuminant=_text(doc, p, "illuminant"), edge_target=_edge_target(doc, p))
