"""Colour charts: reference patch values and layout, loaded from data files in ``charts/``.

A chart is a JSON file (format in ``charts/README.md``): patch names and CIELAB (D65) reference
values in row-major order, the grid layout, white point, observer and provenance. The built-in
``safecolor`` chart is the SAFE-COLOR reference Macbeth ColorChecker. Users add a chart by adding a
file (or passing its path), not code.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.colour.colorimetry import lab_to_srgb
from fidelity.errors import FidelityError, InputFileError, InvalidValueError, unknown_name
from fidelity.resources import resource_dir

__all__ = [
    "DEFAULT_CHART",
    "DEFAULT_REFERENCE",
    "SCENE_REFERENCE",
    "Chart",
    "Reference",
    "available_charts",
    "load_chart",
    "load_reference",
]

#: The chart of the SAFE-COLOR calibration table.
DEFAULT_CHART = "safecolor"


@dataclass(frozen=True)
class Chart:
    """A colour chart: named patches with reference CIELAB values on a rows x cols grid.

    ``lab`` is (rows*cols, 3) CIELAB relative to ``whitepoint`` (D65 for every shipped chart),
    patches in row-major order with the top-left patch (as seen) first.
    """

    name: str
    title: str
    patch_names: tuple[str, ...]
    lab: NDArray[np.float64]
    rows: int
    cols: int
    whitepoint: str = "D65"
    observer: str = "CIE 1931 2 degree"
    provenance: str = ""
    source: str = ""
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def srgb_unclipped(self) -> NDArray[np.float64]:
        """Encoded sRGB of the reference Lab, (n, 3), not clipped (out-of-gamut patches leave [0, 1])."""
        return np.asarray(lab_to_srgb(self.lab), dtype=np.float64)

    @property
    def srgb(self) -> NDArray[np.float64]:
        """The chart image of SAFE-COLOR: reference Lab -> sRGB, clipped to [0, 1], (n, 3)."""
        return np.clip(self.srgb_unclipped, 0.0, 1.0)

    @property
    def neutral_indices(self) -> tuple[int, ...]:
        """Indices of the achromatic patches (reference C*ab < 2), e.g. the bottom row of a Macbeth chart."""
        chroma = np.hypot(self.lab[:, 1], self.lab[:, 2])
        return tuple(int(i) for i in np.flatnonzero(chroma < 2.0))

    def to_json(self) -> dict[str, Any]:
        """The chart as the JSON document it was loaded from (normalised)."""
        return {
            "name": self.name,
            "title": self.title,
            "layout": {"rows": self.rows, "cols": self.cols},
            "colour_space": "CIE 1976 L*a*b*",
            "whitepoint": self.whitepoint,
            "observer": self.observer,
            "provenance": self.provenance,
            "patches": [
                {"name": n, "lab": [float(v) for v in lab]}
                for n, lab in zip(self.patch_names, self.lab, strict=True)
            ],
        }


def available_charts() -> list[str]:
    """Names of the charts that ship with fidelity (files ``charts/<name>.json``)."""
    return sorted(p.stem for p in resource_dir("charts").glob("*.json"))


def _chart_from_document(doc: Any, source: str) -> Chart:
    def bad(msg: str) -> InvalidValueError:
        return InvalidValueError(f"{source}: {msg}")

    if not isinstance(doc, dict):
        raise bad("a chart file must hold a JSON object")
    try:
        rows = int(doc["layout"]["rows"])
        cols = int(doc["layout"]["cols"])
        patches = doc["patches"]
    except (KeyError, TypeError, ValueError) as exc:
        raise bad(f"missing or invalid field {exc}; need layout.rows, layout.cols, patches") from None
    if rows < 1 or cols < 1:
        raise bad(f"layout {rows} x {cols} is empty")
    if not isinstance(patches, list) or len(patches) != rows * cols:
        n = len(patches) if isinstance(patches, list) else "no"
        raise bad(f"layout {rows} x {cols} needs {rows * cols} patches, found {n}")
    names: list[str] = []
    labs: list[list[float]] = []
    for i, p in enumerate(patches):
        try:
            names.append(str(p["name"]))
            lab = [float(v) for v in p["lab"]]
        except (KeyError, TypeError, ValueError):
            raise bad(f"patch {i + 1} needs 'name' and a numeric 'lab' [L, a, b]") from None
        if len(lab) != 3 or not np.all(np.isfinite(lab)):
            raise bad(f"patch {i + 1} ({names[-1]!r}): 'lab' must be 3 finite numbers, got {p['lab']}")
        labs.append(lab)
    lab_arr = np.array(labs, dtype=np.float64)
    lab_arr.setflags(write=False)
    whitepoint = str(doc.get("whitepoint", "D65"))
    if whitepoint != "D65":
        raise bad(f"whitepoint {whitepoint!r} is not supported; reference Lab must be relative to D65")
    known = {"name", "title", "layout", "colour_space", "whitepoint", "observer", "provenance", "patches"}
    return Chart(
        name=str(doc.get("name", Path(source).stem)),
        title=str(doc.get("title", "")),
        patch_names=tuple(names),
        lab=lab_arr,
        rows=rows,
        cols=cols,
        whitepoint=whitepoint,
        observer=str(doc.get("observer", "CIE 1931 2 degree")),
        provenance=str(doc.get("provenance", "")),
        source=source,
        extra={k: v for k, v in doc.items() if k not in known},
    )


def load_chart(name_or_path: str | Path = DEFAULT_CHART) -> Chart:
    """Load a chart by built-in name (see :func:`available_charts`) or from a JSON file path."""
    text_name = str(name_or_path)
    builtin = resource_dir("charts") / f"{text_name}.json"
    path = Path(name_or_path)
    if "/" not in text_name and not text_name.endswith(".json") and builtin.is_file():
        path = builtin
    elif not path.is_file():
        if path.suffix or "/" in text_name:
            raise InputFileError(f"{path}: chart file does not exist")
        raise unknown_name("chart", text_name, available_charts())
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: cannot read chart file ({exc})") from None
    except json.JSONDecodeError as exc:
        raise InputFileError(f"{path}: not valid JSON ({exc})") from None
    return _chart_from_document(doc, str(path))


#: Reference choices besides a chart name or path: ``scene`` (spectral chart under the illuminant).
SCENE_REFERENCE = "scene"
#: Default reference of every command (render, check, audit, gate): the chart's spectra under the
#: scene illuminant (``scene``); ``safecolor`` is the paper's Lab table (older D50-era data).
DEFAULT_REFERENCE = "scene"


@dataclass(frozen=True)
class Reference:
    """Reference colours of the chart patches: names, CIELAB D65, clipped sRGB, neutral indices."""

    name: str
    patch_names: tuple[str, ...]
    lab: np.ndarray
    srgb: np.ndarray
    neutral_indices: tuple[int, ...]
    rows: int = 4
    cols: int = 6
    conventions: dict[str, Any] = field(default_factory=dict)


def load_reference(reference: str = DEFAULT_REFERENCE, illuminant: str = "D65") -> Reference:
    """The reference chart: ``"scene"`` (BabelColor Average spectra under ``illuminant``,
    adapted to D65, :func:`fidelity.colour.spectral.scene_reference`), or a chart name/path
    (``"safecolor"``: the paper's Lab values, :func:`fidelity.colour.charts.load_chart`)."""
    if reference == SCENE_REFERENCE:
        from fidelity.colour.spectral import scene_reference

        chart = load_chart("safecolor")
        sr = scene_reference(illuminant)
        lab = np.asarray(sr.lab, dtype=np.float64)
        return Reference(
            name=f"scene ({sr.conventions.get('reflectances', '')} under "
                 f"{sr.conventions.get('illuminant', illuminant)})",
            patch_names=tuple(sr.patch_names) if sr.patch_names else chart.patch_names,
            lab=lab, srgb=np.clip(np.asarray(sr.srgb, np.float64), 0, 1),
            neutral_indices=chart.neutral_indices,  # same layout as the SAFE-COLOR chart
            conventions=dict(sr.conventions),
        )
    try:
        chart = load_chart(reference)
    except Exception as exc:  # an unknown name reads better with the choices listed

        if isinstance(exc, FidelityError) and not os.path.exists(reference):
            raise unknown_name("reference", reference,
                               [SCENE_REFERENCE, *available_charts()]) from None
        raise
    return Reference(
        name=chart.name, patch_names=chart.patch_names, lab=np.asarray(chart.lab, np.float64),
        srgb=np.asarray(chart.srgb, np.float64), neutral_indices=chart.neutral_indices,
        rows=chart.rows, cols=chart.cols,
        conventions={"reference": f"chart {chart.name!r}: {chart.title}",
                     "provenance": chart.provenance},
    )
