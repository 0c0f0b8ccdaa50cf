"""Colour charts: reference patch values and layout, loaded from data files in ``charts/``.

A chart is a JSON file (format in ``charts/README.md``): patch names and CIELAB (D65) reference
values in row-major order, the grid layout, white point, observer and provenance. The built-in
``safecolor`` chart is the SAFE-COLOR reference Macbeth ColorChecker. Users add a chart by adding a
file (or passing its path), not code.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.colour.colorimetry import lab_to_srgb
from fidelity.colour.spectral import scene_reference
from fidelity.core import schema as sc
from fidelity.core.errors import FidelityError, InputFileError, unknown_name
from fidelity.core.fileio import cached_while_unchanged, display_path
from fidelity.core.record import record
from fidelity.core.resources import resource_dir

__all__ = [
    "CHART_SCHEMA",
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


def _read_only(a: NDArray[np.float64]) -> NDArray[np.float64]:
    a.setflags(write=False)
    return a


@record
class Chart:
    """A colour chart: named patches with reference CIELAB values on a rows x cols grid.

    ``lab`` is (rows*cols, 3) CIELAB relative to ``whitepoint`` (D65 for every shipped chart),
    patches in row-major order with the top-left patch (as seen) first.

    Attributes
    ----------
    name
        The chart's name (``safecolor`` for the shipped chart; a file's ``name`` field, else
        the file's stem).
    title
        Its human-readable title ("" when the file gives none).
    patch_names
        One name per patch, rows*cols of them, in the order of ``lab``.
    lab
        Reference CIELAB of the patches, shape (rows*cols, 3), read-only float64: L* in
        [0, 100], a*, b* within +-:data:`LAB_LIMIT`; relative to ``whitepoint``.
    rows
        Rows of the grid, >= 1 (4 for a Macbeth ColorChecker).
    cols
        Columns of the grid, >= 1 (6 for a Macbeth ColorChecker).
    whitepoint
        White point of ``lab``; ``D65`` (the only one a chart file may give).
    observer
        The colorimetric observer of ``lab`` (``CIE 1931 2 degree``).
    provenance
        Where the reference values come from (free text; "" when unknown).
    source
        The file it was loaded from, as printable text ("" for one built in code).
    extra
        The chart file's fields beyond :data:`CHART_SCHEMA`'s, kept as read; not compared.
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

    @cached_property
    def srgb_unclipped(self) -> NDArray[np.float64]:
        """Encoded sRGB of the reference Lab, (n, 3), not clipped (out-of-gamut patches leave
        [0, 1]); computed once, read-only."""
        return _read_only(np.array(lab_to_srgb(self.lab), dtype=np.float64))

    @cached_property
    def srgb(self) -> NDArray[np.float64]:
        """The chart image of SAFE-COLOR: reference Lab -> sRGB, clipped to [0, 1], (n, 3);
        computed once, read-only (every transform's chart ΔE starts from it)."""
        return _read_only(np.clip(self.srgb_unclipped, 0.0, 1.0))

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


def _layout_fits(doc: Mapping[str, Any]) -> tuple[str, str] | None:
    rows, cols = doc["layout"]["rows"], doc["layout"]["cols"]
    if rows < 1 or cols < 1:
        return "layout", f"layout {rows} x {cols} is empty"
    if len(doc["patches"]) != rows * cols:
        return "patches", (f"layout {rows} x {cols} needs {rows * cols} patches, found "
                           f"{len(doc['patches'])}")
    return None


#: Largest magnitude of a reference CIELAB coordinate (L* of a reflective chart is in
#: [0, 100]; a* and b* of real colours stay within +-200).
LAB_LIMIT = 1000.0


def _lab_range(doc: Mapping[str, Any]) -> tuple[str, str] | None:
    for k, p in enumerate(doc["patches"]):
        if not 0.0 <= p["lab"][0] <= 100.0:
            return f"patches[{k}].lab", f"L* must be in [0, 100], got {p['lab'][0]}"
    return None


#: Most patches of a chart (a 14 x 10 ColorChecker SG has 140).
MAX_CHART_PATCHES = 1024

#: A chart file (``charts/README.md``): layout, white point and the patches' reference Lab.
CHART_SCHEMA = sc.Table(fields=(
    sc.Field("name", sc.String(nonempty=True)),
    sc.Field("title", sc.String(), default=""),
    sc.Field("layout", sc.Table(fields=(
        sc.Field("rows", sc.Integer(lo=0, hi=MAX_CHART_PATCHES), required=True),
        sc.Field("cols", sc.Integer(lo=0, hi=MAX_CHART_PATCHES), required=True),
    ), extra=True), required=True),
    sc.Field("colour_space", sc.String()),
    sc.Field("whitepoint", sc.String(choices=("D65",), ignore_case=False,
                                     describe="D65 (reference Lab must be relative to D65)"),
             default="D65"),
    sc.Field("observer", sc.String(), default="CIE 1931 2 degree"),
    sc.Field("provenance", sc.String(), default=""),
    sc.Field("patches", sc.ListOf(sc.Table(fields=(
        sc.Field("name", sc.String(), required=True),
        sc.Field("lab", sc.ListOf(sc.Number(lo=-LAB_LIMIT, hi=LAB_LIMIT), min_items=3,
                                  max_items=3, describe="3 finite numbers [L, a, b]"),
                 required=True),
    ), extra=True), max_items=MAX_CHART_PATCHES), required=True),
), extra=True, rules=(sc.Check(_layout_fits), sc.Check(_lab_range)))

#: Largest chart file read, in bytes.
MAX_CHART_BYTES = 4 << 20


def _chart_from_document(doc: Any, source: str) -> Chart:
    """A :class:`Chart` from a parsed chart file, validated against :data:`CHART_SCHEMA`."""
    v = sc.validate(doc, CHART_SCHEMA, source)
    lab_arr = np.array([p["lab"] for p in v["patches"]], dtype=np.float64).reshape(-1, 3)
    lab_arr.setflags(write=False)
    known = {f.name for f in CHART_SCHEMA.fields}
    return Chart(
        name=str(v.get("name", Path(source).stem)),
        title=v["title"],
        patch_names=tuple(p["name"] for p in v["patches"]),
        lab=lab_arr,
        rows=v["layout"]["rows"],
        cols=v["layout"]["cols"],
        whitepoint=v["whitepoint"],
        observer=v["observer"],
        provenance=v["provenance"],
        source=source,
        extra={k: val for k, val in v.items() if k not in known},
    )


def load_chart(name_or_path: str | Path = DEFAULT_CHART) -> Chart:
    """Load a chart by built-in name (see :func:`available_charts`) or from a JSON file path.

    The file (``charts/README.md``) is validated against :data:`CHART_SCHEMA` and read once
    a process while it is unchanged.

    Parameters
    ----------
    name_or_path
        A shipped chart's name (:func:`available_charts`; default :data:`DEFAULT_CHART`,
        ``safecolor``), or the path of a chart JSON file (at most :data:`MAX_CHART_BYTES`
        bytes, :data:`MAX_CHART_PATCHES` patches).

    Returns
    -------
    Chart
        The chart: frozen, its ``lab`` read-only.

    Raises
    ------
    InputFileError
        A path (a name with ``/`` or a suffix) that does not exist; an unreadable file, or
        one that is not JSON or does not fit the schema (``SchemaError``, also an
        :class:`InvalidValueError`: a layout whose rows x cols differs from the number of
        patches, L* outside [0, 100], a white point other than D65). Exit code 2.
    UnknownNameError
        A plain name that is neither a shipped chart nor an existing file. Exit code 2.
    """
    text_name = str(name_or_path)
    builtin = resource_dir("charts") / f"{text_name}.json"
    path = Path(name_or_path)
    if "/" not in text_name and not text_name.endswith(".json") and builtin.is_file():
        path = builtin
    elif not path.is_file():
        if path.suffix or "/" in text_name:
            raise InputFileError(f"{path}: chart file does not exist")
        raise unknown_name("chart", text_name, available_charts())
    return _load_chart_file(path)


@cached_while_unchanged(maxsize=16)
def _load_chart_file(path: Path) -> Chart:
    """The chart in ``path``, read and validated once a process while the file is unchanged
    (a :class:`Chart` is frozen, its ``lab`` read-only)."""
    doc = sc.load_document(path, fmt="json", max_bytes=MAX_CHART_BYTES, what="chart file")
    return _chart_from_document(doc, display_path(path))


#: Reference choices besides a chart name or path: ``scene`` (spectral chart under the illuminant).
SCENE_REFERENCE = "scene"
#: Default reference of every command (render, check, audit, gate): the chart's spectra under the
#: scene illuminant (``scene``); ``safecolor`` is the paper's Lab table (older D50-era data).
DEFAULT_REFERENCE = "scene"


@record
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


def load_reference(reference: str = DEFAULT_REFERENCE, illuminant: str = "D65",
                   cat: str = "Bradford") -> Reference:
    """The reference chart: ``"scene"`` (BabelColor Average spectra under ``illuminant``,
    adapted to D65 by the chromatic adaptation ``cat``,
    :func:`fidelity.colour.spectral.scene_reference`), or a chart name/path (``"safecolor"``:
    the paper's Lab values, :func:`fidelity.colour.charts.load_chart`)."""
    if reference == SCENE_REFERENCE:
        chart = load_chart("safecolor")
        sr = scene_reference(illuminant, cat=cat)
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
