"""Reports: JSON for machines (documented schema), self-contained HTML for people, JUnit XML for CI.

The JSON report (``schema_version`` :data:`SCHEMA_VERSION`) is described by the JSON Schema in
``fidelity/data/schemas/report.schema.json`` (:func:`report_schema`). It is the same for
``fidelity audit``, ``check`` and ``gate``; keys that do not apply are ``null``:

- ``mean_delta_e``, ``max_delta_e``, ``worst_patch``, ``patches`` (per patch ``delta_e``,
  ``delta_l``, ``delta_c``, ``delta_h``, ``lab``, ``reference_lab``, ``srgb``, ...): the chart
  measurement (CIEDE2000, Lab D65);
- ``exposure_ev``, ``bad_pixels``: the audit of an image (``null`` for a render);
- ``source``: the image (path, sha256, format, layer, corners, how they were found, encoding) or the render
  (camera, illuminant, renderer, variant, seconds);
- ``prediction``: ΔE -> ΔmAP (:meth:`fidelity.prediction.table.Prediction.to_dict`);
- ``verdict``: pass/fail of the criterion (:meth:`fidelity.prediction.verdict.Verdict.to_dict`);
- ``provenance``: tool version, time, Python and libraries, input sha256, tables (name, path,
  sha256), conventions.

The HTML report embeds its plots as base64 PNG (matplotlib, Agg): the chart as swatches
(reference left, measured right, in each patch), ΔE00 per patch as bars, and the ΔE -> ΔmAP
curves with this chart's point; then the verdict and the provenance.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
import os
import platform
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np

from fidelity import __version__
from fidelity.chart.measure import ChartMeasurement
from fidelity.fileio import write_json_atomic, write_text_atomic
from fidelity.prediction.table import Prediction, predict_curve
from fidelity.prediction.verdict import Verdict

#: Version of the JSON report layout (bump on incompatible change).
SCHEMA_VERSION = "1.0"


def report_schema_path() -> Path:
    """Path of the JSON Schema of the report."""
    from fidelity.resources import resource_dir

    return resource_dir("data") / "schemas" / "report.schema.json"


def report_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the JSON report."""
    return json.loads(report_schema_path().read_text(encoding="utf-8"))


def _sha256_or_none(path: str | os.PathLike[str] | None) -> str | None:
    if not path:
        return None
    from fidelity.fileio import file_sha256

    try:
        return file_sha256(path)
    except OSError:
        return None


def _library_versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("numpy", "scipy", "colour-science", "OpenImageIO", "OpenEXR", "matplotlib",
                 "mitsuba"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


def _clean(obj: Any) -> Any:
    """Make ``obj`` strict-JSON: numpy scalars/arrays to Python, NaN/Inf to ``None``."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if np.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def build_report(
    command: str,
    measurement: ChartMeasurement,
    *,
    source: dict[str, Any],
    prediction: Prediction | None = None,
    verdict: Verdict | None = None,
    exposure_ev: float | None = None,
    bad_pixels: dict[str, Any] | None = None,
    patch_extras: list[dict[str, Any]] | None = None,
    conventions: dict[str, Any] | None = None,
    details: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Assemble the JSON report (see the module docstring for the layout)."""
    m = measurement.to_dict()
    patches = m["patches"]
    if patch_extras:
        for p, extra in zip(patches, patch_extras, strict=True):
            p.update(extra)
    tables: dict[str, Any] = {}
    if prediction is not None:
        t = prediction.table
        tables["prediction"] = {"name": t.name, "kind": t.kind, "path": str(t.path) if t.path else None,
                                "sha256": _sha256_or_none(t.path)}
        from fidelity.resources import resource_dir

        cal = resource_dir("data") / "calibration-safecolor.json"
        tables["calibration"] = {"name": "calibration-safecolor", "path": str(cal),
                                 "sha256": _sha256_or_none(cal)}
    conv = {
        "delta_e": "CIEDE2000 (kL = kC = kH = 1), CIE 1976 L*a*b* relative to D65, CIE 1931 2° "
                   "observer; chart ΔE = mean over the 24 patches",
        "srgb": "IEC 61966-2-1 (piecewise transfer, 0.04045 / 0.0031308, exponent 2.4)",
        "dmap_points": "percentage points of mAP@[.50:.95] (100*(baseline-transformed))",
        "dmap_relative": "percent of the baseline mAP",
        **(conventions or {}),
    }
    report = {
        "schema_version": SCHEMA_VERSION,
        "command": command,
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "mean_delta_e": m["mean_delta_e"],
        "max_delta_e": m["max_delta_e"],
        "worst_patch": m.get("worst_patch"),
        "patches": patches,
        "exposure_ev": exposure_ev,
        "bad_pixels": bad_pixels,
        "source": source,
        "prediction": prediction.to_dict() if prediction is not None else None,
        "verdict": verdict.to_dict() if verdict is not None else None,
        "details": details or {},
        "provenance": {
            "tool": "fidelity",
            "version": __version__,
            "python": sys.version.split()[0],
            "platform": platform.platform(),
            "libraries": _library_versions(),
            "input_sha256": source.get("sha256"),
            "tables": tables,
            "conventions": conv,
        },
    }
    return _clean(report)


def write_json_report(path: str | os.PathLike[str], report: dict[str, Any],
                      protect: tuple[str, ...] = ()) -> Path:
    """Write the JSON report atomically (strict JSON: no NaN)."""
    _refuse_inputs(path, protect)
    return write_json_atomic(path, report)


def _refuse_inputs(path: str | os.PathLike[str], protect: tuple[str, ...]) -> None:
    from fidelity.fileio import check_outputs

    check_outputs({"report": path}, {f"input {i + 1}": p for i, p in enumerate(protect) if p})


# --------------------------------------------------------------------------------- plots

def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def plot_swatches(report: dict[str, Any]) -> str:
    """Base64 PNG: the chart, each patch split into reference (left) and measured (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    patches = report["patches"]
    rows, cols = 4, 6
    cell, gap = 60, 16
    img = np.full((rows * (cell + gap) + gap, cols * (cell + gap) + gap, 3), 0.12)
    for k, p in enumerate(patches[: rows * cols]):
        r, c = divmod(k, cols)
        y0, x0 = gap + r * (cell + gap), gap + c * (cell + gap)
        ref = np.clip(p.get("reference_srgb") or [0.5, 0.5, 0.5], 0, 1)
        meas = np.clip(p.get("srgb") or [0.5, 0.5, 0.5], 0, 1)
        img[y0:y0 + cell, x0:x0 + cell // 2] = ref
        img[y0:y0 + cell, x0 + cell // 2:x0 + cell] = meas
    fig, ax = plt.subplots(figsize=(7.2, 5.2))
    ax.imshow(img, interpolation="nearest")
    for k, p in enumerate(patches[: rows * cols]):
        r, c = divmod(k, cols)
        y0, x0 = gap + r * (cell + gap), gap + c * (cell + gap)
        ax.text(x0 + cell / 2, y0 + cell + gap * 0.5, f"{p['name']}\nΔE {p['delta_e']:.2f}",
                ha="center", va="center", fontsize=5.5, color="white", linespacing=1.0)
    ax.set_title("reference (left half) | measured (right half) per patch", fontsize=9)
    ax.axis("off")
    return _png(fig)


def plot_chart_location(pixels: np.ndarray, location: Any, *, encoding: str = "linear",
                        exposure_ev: float = 0.0, found: bool = False) -> str:
    """Base64 PNG: the image with every patch's sampling window outlined and numbered.

    ``location`` is a :class:`fidelity.chart.locate.ChartLocation`. Linear pixels are shown at the
    audit's exposure (``2**exposure_ev``), sRGB-encoded; NaN/Inf show as black. The corner
    patches are labelled, so a wrong orientation or a grid off the patches is seen at once.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fidelity.chart.locate import CORNER_PATCHES, apply_homography
    from fidelity.colour import colorimetry as cm

    arr = np.asarray(pixels, dtype=np.float64)
    arr = np.where(np.isfinite(arr), arr, 0.0)
    if encoding == "linear":
        arr = cm.delinearize_srgb(np.clip(arr * 2.0 ** exposure_ev, 0.0, 1.0))
    arr = np.clip(arr, 0.0, 1.0)
    height, width = arr.shape[:2]
    fig, ax = plt.subplots(figsize=(7.2, 7.2 * height / max(width, 1)))
    ax.imshow(arr, interpolation="antialiased")
    half = location.window / 2.0
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half],
                       [-half, -half]])
    cols = location.cols
    for k in range(location.rows * cols):
        r, c = divmod(k, cols)
        quad = apply_homography(location.homography, square + (c, r))
        ax.plot(quad[:, 0], quad[:, 1], color="white", lw=0.8)
        ax.plot(quad[:, 0], quad[:, 1], color="black", lw=0.8, ls=(0, (2, 2)))
        ax.text(*location.centres[k], str(k + 1), ha="center", va="center", fontsize=6,
                color="white", bbox={"facecolor": "black", "alpha": 0.5, "pad": 0.5, "lw": 0})
    for name, (x, y) in zip(CORNER_PATCHES, location.corners, strict=True):
        ax.text(x, y + location.pitch_px * 0.3, name, fontsize=6, color="yellow", ha="center",
                va="top", bbox={"facecolor": "black", "alpha": 0.6, "pad": 0.5, "lw": 0})
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)
    how = "found in the image" if found else "from --corners"
    ax.set_title(f"sampling windows ({location.window:g} patch pitch), corners {how}", fontsize=9)
    ax.axis("off")
    return _png(fig)


def plot_delta_e_bars(report: dict[str, Any], limit: float | None = None) -> str:
    """Base64 PNG: ΔE00 per patch as bars, with the mean (and the ΔE limit, if any)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    patches = report["patches"]
    names = [p["name"] for p in patches]
    de = [p["delta_e"] for p in patches]
    colours = [np.clip(p.get("srgb") or [0.4, 0.4, 0.4], 0, 1) for p in patches]
    fig, ax = plt.subplots(figsize=(8.5, 3.4))
    ax.bar(range(len(de)), de, color=colours, edgecolor="black", linewidth=0.5)
    ax.axhline(report["mean_delta_e"], color="tab:blue", ls="--", lw=1,
               label=f"mean {report['mean_delta_e']:.2f}")
    if limit is not None:
        ax.axhline(limit, color="tab:red", ls=":", lw=1.2, label=f"limit {limit:g}")
    ax.set_xticks(range(len(de)), names, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("ΔE00")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return _png(fig)


def plot_prediction_curve(prediction: Prediction, limit_dmap: float | None = None) -> str:
    """Base64 PNG: the table's ΔE -> loss curves with this chart's point on each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    de = prediction.delta_e
    xmax = max(30.0, de * 1.2)
    grid = np.linspace(0.0, xmax, 601)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    labels = {"dmap_points": "ΔmAP (points)", "dmap_relative": "ΔmAP (% of baseline)",
              "dap_person_points": "person ΔAP (points)", "dap_bicycle_points": "bicycle ΔAP (points)"}
    colors = {"dmap_points": "tab:red", "dmap_relative": "tab:orange",
              "dap_person_points": "tab:blue", "dap_bicycle_points": "tab:green"}
    for col, label in labels.items():
        y = predict_curve(grid, col, size=prediction.size, table=prediction.table,
                          method=prediction.method)
        if np.all(np.isnan(y)):
            continue
        ax.plot(grid, y, color=colors[col], lw=1.3, label=label,
                ls="-" if col != "dmap_relative" else "--")
        v = prediction.columns[col].value
        if v is not None:
            ax.plot([de], [v], "o", color=colors[col], ms=7, mec="black")
    ax.axvline(de, color="grey", lw=0.8, ls=":")
    ax.annotate(f"this chart: ΔE {de:.2f}", (de, 0), xytext=(5, 5), textcoords="offset points",
                fontsize=8)
    rng = prediction.columns["dmap_points"].delta_e_range
    if rng is not None and rng[1] < xmax:
        ax.axvspan(rng[1], xmax, color="grey", alpha=0.12, label="beyond the table (ceiling)")
    if limit_dmap is not None:
        ax.axhline(limit_dmap, color="black", ls=":", lw=1, label=f"limit {limit_dmap:g}")
    ax.set_xlabel("chart ΔE00 (mean over 24 patches)")
    ax.set_ylabel("predicted loss" + (" (upper bound)" if prediction.table.kind ==
                                      "published-bounds" else ""))
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(0, 105)
    ax.set_xlim(0, xmax)
    ax.set_title(f"table {prediction.table.name} ({prediction.table.kind}), detector size "
                 f"{prediction.size_used}, {prediction.method} interpolation", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    return _png(fig)


# ---------------------------------------------------------------------------------- HTML

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;
margin:2em auto;padding:0 1em;color:#222}h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.6em;
border-bottom:1px solid #ddd}table{border-collapse:collapse;font-size:.85em}td,th{border:1px solid
#ddd;padding:3px 7px;text-align:right}th{background:#f4f4f4}td.l,th.l{text-align:left}
.verdict{padding:.8em 1em;border-radius:6px;font-size:1.1em;font-weight:600}
.pass{background:#e3f5e1;color:#1d5e1a}.fail{background:#fbe3e1;color:#8a1c12}
.info{background:#eef2fb;color:#1f3a73}pre{background:#f7f7f7;padding:.8em;overflow-x:auto;
font-size:.78em}img{max-width:100%}.note{color:#555;font-size:.85em}
"""


def _fmt(v: Any, nd: int = 2) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.{nd}f}"
    return html.escape(str(v))


def render_html(report: dict[str, Any], prediction: Prediction | None = None,
                location_png: str | None = None) -> str:
    """The self-contained HTML report of a JSON report (plots embedded as base64 PNG).

    ``location_png``: the base64 PNG of :func:`plot_chart_location`, shown for an image."""
    e = html.escape
    verdict = report.get("verdict")
    src = report.get("source") or {}
    title = src.get("camera") or src.get("path") or "chart"
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>fidelity "
             f"report: {e(str(title))}</title><style>{_CSS}</style></head><body>",
             f"<h1>Colour fidelity report: {e(str(title))}</h1>"]
    if verdict:
        cls = "pass" if verdict["passed"] else "fail"
        parts.append(f"<div class='verdict {cls}'>{e(verdict['message'])}</div>")
    else:
        parts.append(f"<div class='verdict info'>mean ΔE00 {report['mean_delta_e']:.2f} "
                     f"(no gate applied)</div>")
    pred = report.get("prediction")
    rows = [("mean ΔE00 (chart ΔE)", _fmt(report["mean_delta_e"])),
            ("max ΔE00", f"{_fmt(report['max_delta_e'])} ({e(str(report.get('worst_patch')))})")]
    if report.get("exposure_ev") is not None:
        rows.append(("exposure correction", f"{report['exposure_ev']:+.3f} EV"))
    if report.get("bad_pixels"):
        bp = report["bad_pixels"]
        rows.append(("bad pixels in windows (NaN/Inf/negative)",
                     f"{bp.get('total', 0)} ({bp.get('nan', 0)}/{bp.get('inf', 0)}/"
                     f"{bp.get('negative', 0)})"))
    if pred:
        b = "≤ " if pred.get("bound") else ""
        rows += [
            ("predicted ΔmAP, percentage points", b + _fmt(pred["dmap_points"])),
            ("predicted ΔmAP, % of baseline", b + _fmt(pred["dmap_relative"])),
            ("predicted person ΔAP, points", b + _fmt(pred["dap_person_points"])),
            ("predicted bicycle ΔAP, points", b + _fmt(pred["dap_bicycle_points"])),
            ("prediction table", e(f"{pred['table']['name']} ({pred['table']['kind']}), detector size "
                                   f"{pred['size_used']}")),
        ]
    parts.append("<h2>Summary</h2><table>" + "".join(
        f"<tr><th class='l'>{e(k)}</th><td class='l'>{v}</td></tr>" for k, v in rows) + "</table>")
    if pred and pred.get("notes"):
        parts.append("<ul class='note'>" + "".join(f"<li>{e(n)}</li>" for n in pred["notes"])
                     + "</ul>")
    limit_de = None
    limit_dmap = None
    if verdict:
        crit = verdict["criterion"]
        if crit["kind"] == "max-delta-e":
            limit_de = crit["limit"]
        elif crit["cls"] == "all" and crit["unit"] == "points":
            limit_dmap = crit["limit"]
    if location_png:
        parts.append("<h2>Where the patches were sampled</h2>"
                     f"<img alt='sampling windows' src='data:image/png;base64,{location_png}'>")
    parts.append("<h2>Chart: reference against measured</h2>"
                 f"<img alt='swatches' src='data:image/png;base64,{plot_swatches(report)}'>")
    parts.append("<h2>ΔE00 per patch</h2>"
                 f"<img alt='delta E bars' src='data:image/png;base64,"
                 f"{plot_delta_e_bars(report, limit_de)}'>")
    if prediction is not None:
        parts.append("<h2>ΔE → predicted detection loss</h2>"
                     f"<img alt='prediction curve' src='data:image/png;base64,"
                     f"{plot_prediction_curve(prediction, limit_dmap)}'>")
        for col, c in pred["columns"].items():
            parts.append(f"<div class='note'>{e(col)}: {e(c['status'])}: {e(c['note'])}</div>")
    head = ("<tr><th class='l'>patch</th><th>ΔE00</th><th>ΔL'</th><th>ΔC'</th><th>ΔH'</th>"
            "<th>L*</th><th>a*</th><th>b*</th><th>ref L*</th><th>ref a*</th><th>ref b*</th></tr>")
    body = "".join(
        f"<tr><td class='l'>{e(p['name'])}</td><td>{_fmt(p['delta_e'])}</td>"
        f"<td>{_fmt(p['delta_l'])}</td><td>{_fmt(p['delta_c'])}</td><td>{_fmt(p['delta_h'])}</td>"
        + "".join(f"<td>{_fmt(v)}</td>" for v in (p.get("lab") or [None] * 3))
        + "".join(f"<td>{_fmt(v)}</td>" for v in (p.get("reference_lab") or [None] * 3))
        + "</tr>" for p in report["patches"])
    parts.append(f"<h2>Patches</h2><table>{head}{body}</table>")
    if pred and pred.get("transforms"):
        trs = "".join(
            f"<tr><td class='l'>{e(t['transform'])}</td><td>{_fmt(t['param'], 4)}</td>"
            f"<td class='l'>{e(str(t['method']))}</td></tr>" for t in pred["transforms"])
        parts.append(f"<h2>SAFE-COLOR transforms that give ΔE {pred['delta_e']:.2f} on the "
                     f"chart</h2><table><tr><th class='l'>transform</th><th>parameter</th>"
                     f"<th class='l'>how</th></tr>{trs}</table>")
    prov = report["provenance"]
    parts.append("<h2>Provenance</h2><table>" + "".join(
        f"<tr><th class='l'>{e(k)}</th><td class='l'>{e(str(v))}</td></tr>" for k, v in (
            ("tool", f"fidelity {prov['version']}"), ("created", report["created"]),
            ("input sha256", prov.get("input_sha256") or "–"),
            ("python", prov["python"]), ("platform", prov["platform"]),
            ("libraries", ", ".join(f"{k} {v}" for k, v in prov["libraries"].items())),
        )) + "</table>")
    parts.append("<h3>Source</h3><pre>" + e(json.dumps(src, indent=1, ensure_ascii=False))
                 + "</pre>")
    parts.append("<h3>Tables</h3><pre>" + e(json.dumps(prov["tables"], indent=1,
                                                        ensure_ascii=False)) + "</pre>")
    if pred:
        parts.append("<h3>Prediction table provenance</h3><pre>" + e(json.dumps(
            pred["table"]["provenance"], indent=1, ensure_ascii=False)) + "</pre>")
    parts.append("<h3>Conventions</h3><pre>" + e(json.dumps(prov["conventions"], indent=1,
                                                             ensure_ascii=False)) + "</pre>")
    parts.append("<p class='note'>JSON schema: fidelity/data/schemas/report.schema.json "
                 f"(version {e(report['schema_version'])}).</p></body></html>")
    return "\n".join(parts)


def write_html_report(path: str | os.PathLike[str], report: dict[str, Any],
                      prediction: Prediction | None = None, protect: tuple[str, ...] = (),
                      location_png: str | None = None) -> Path:
    """Write the HTML report atomically."""
    _refuse_inputs(path, protect)
    return write_text_atomic(path, render_html(report, prediction, location_png))


# --------------------------------------------------------------------------------- JUnit

@dataclass(frozen=True)
class GateCase:
    """One gated input for JUnit: its test-case ``name``, its ``report`` (None on error), the
    ``error`` message (exit code 2) and the ``seconds`` it took."""

    name: str
    report: dict[str, Any] | None = None
    error: str | None = None
    seconds: float = 0.0


def _junit_properties(report: dict[str, Any]) -> list[tuple[str, str]]:
    pred = report.get("prediction") or {}
    values = (("mean_delta_e", report.get("mean_delta_e")),
              ("max_delta_e", report.get("max_delta_e")),
              ("worst_patch", report.get("worst_patch")),
              ("dmap_points", pred.get("dmap_points")),
              ("dmap_relative", pred.get("dmap_relative")),
              ("dap_person_points", pred.get("dap_person_points")),
              ("dap_bicycle_points", pred.get("dap_bicycle_points")),
              ("prediction_table", (pred.get("table") or {}).get("name")),
              ("input_sha256", report["provenance"].get("input_sha256")),
              ("fidelity_version", report["provenance"]["version"]))
    return [(k, "" if v is None else str(v)) for k, v in values]


def junit_xml(cases: Sequence[GateCase]) -> str:
    """JUnit XML, one test case per gated input. A failed gate is a ``<failure>``, an error
    (exit code 2) an ``<error>``; the measured values are ``<properties>``: of the test suite
    when there is one case (JUnit's classic place), of each test case when there are several
    (the form pytest's ``record_property`` writes, read by Jenkins and GitLab)."""
    total = sum(c.seconds for c in cases)
    suite = ET.Element("testsuite", name="fidelity", tests=str(len(cases)), failures="0",
                       errors="0", skipped="0", time=f"{total:.3f}")
    suite_props = ET.SubElement(suite, "properties")  # JUnit: properties precede test cases
    failures = errors = 0
    for c in cases:
        case = ET.SubElement(suite, "testcase", classname="fidelity.gate", name=c.name,
                             time=f"{c.seconds:.3f}")
        if c.error is not None:
            errors += 1
            ET.SubElement(case, "error", message=c.error, type="FidelityError").text = c.error
            continue
        if c.report is None:
            continue
        props = suite_props if len(cases) == 1 else ET.SubElement(case, "properties")
        for key, value in _junit_properties(c.report):
            ET.SubElement(props, "property", name=key, value=value)
        verdict = c.report.get("verdict")
        if verdict and not verdict["passed"]:
            failures += 1
            ET.SubElement(case, "failure", message=verdict["message"],
                          type="GateFailure").text = verdict["message"]
        ET.SubElement(case, "system-out").text = "\n".join(summary_lines(c.report))
    suite.set("failures", str(failures))
    suite.set("errors", str(errors))
    if not len(suite_props):
        suite.remove(suite_props)
    root = ET.Element("testsuites", name="fidelity", tests=str(len(cases)),
                      failures=str(failures), errors=str(errors))
    root.append(suite)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_junit(path: str | os.PathLike[str], cases: Sequence[GateCase]) -> Path:
    """Write JUnit XML atomically (see :func:`junit_xml`)."""
    return write_text_atomic(path, junit_xml(cases))


# ------------------------------------------------------------------------------ terminal

def summary_lines(report: dict[str, Any]) -> list[str]:
    """A short, readable verdict for the terminal."""
    lines = []
    found = (report.get("source") or {}).get("corners_found")
    if found:
        lines.append(f"chart found ({found['method']}, {found['swatches']} of 24 patch outlines "
                     f"fitted, orientation {found['orientation']}): --corners "
                     f"{found['corners_text']}")
    space = (report.get("source") or {}).get("colourspace")
    if space and space != "sRGB":
        lines.append(f"RGB primaries: {space}, converted to linear sRGB")
    lines.append(f"chart ΔE00: mean {report['mean_delta_e']:.2f}, max "
                 f"{report['max_delta_e']:.2f} ({report.get('worst_patch')})")
    if report.get("exposure_ev") is not None:
        bp = report.get("bad_pixels") or {}
        kept = (f"; pixels with a negative channel kept in the mean: {bp['negative']}"
                if bp.get("negative") and bp.get("negatives") == "keep" else "")
        lines.append(f"exposure correction {report['exposure_ev']:+.2f} EV; bad pixels "
                     f"excluded: {bp.get('total', 0)}{kept}")
        clipped = (report.get("details") or {}).get("clipped_patches")
        if clipped:
            lines.append("outside [0, 1] in sRGB, clipped like a stored image: "
                         + ", ".join(clipped))
    pred = report.get("prediction")
    if pred:
        b = "<= " if pred.get("bound") else ""

        def f(v: Any) -> str:
            return "n/a" if v is None else f"{b}{v:.2f}"

        kind = ("upper bound, " if pred.get("bound") else
                "measured worst case, " if pred["table"].get("kind") == "measured" else "")
        lines.append(f"predicted ΔmAP: {f(pred['dmap_points'])} percentage points, "
                     f"{f(pred['dmap_relative'])} % of baseline ({kind}table "
                     f"{pred['table']['name']}, detector size {pred['size_used']})")
        lines.append(f"predicted ΔAP: person {f(pred['dap_person_points'])} points, bicycle "
                     f"{f(pred['dap_bicycle_points'])} points")
        if pred.get("out_of_range"):
            lines.append("note: ΔE beyond the table's range; conservative ceiling used")
    if report.get("verdict"):
        lines.append(report["verdict"]["message"])
    return lines


__all__ = [
    "SCHEMA_VERSION",
    "build_report",
    "GateCase",
    "junit_xml",
    "plot_delta_e_bars",
    "plot_prediction_curve",
    "plot_swatches",
    "plot_chart_location",
    "render_html",
    "report_schema",
    "report_schema_path",
    "summary_lines",
    "write_html_report",
    "write_json_report",
    "write_junit",
]
