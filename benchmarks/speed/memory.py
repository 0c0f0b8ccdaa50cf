"""Peak memory (max RSS) and wall time of whole ``fidelity audit`` processes, per megapixel,
beside the image decoder alone (the anchor).

For each size (megapixels, 4:3) a synthetic photo (:func:`tests.fixtures.photos.photo`) is
written as an 8-bit sRGB JPEG (quality 90) in a temporary folder: the 4 x 6 ColorChecker drawn
square to the frame on a grey gradient, its patch pitch ``fill`` of the width divided by 6
(0.9: the chart fills the frame, the largest sampling windows; 0.25: a chart in a scene). Then,
one fresh process each, one after the other in the same run: ``decode (anchor)``, a Python
process that imports OpenImageIO and decodes the JPEG into a ``uint8`` NumPy array (what any
tool that reads the photo must hold); ``audit``, ``python -m fidelity audit PHOTO --json F``
(read, find the chart, measure, predict); ``audit --corners``, the same with the chart's four
corner-patch centres given. The max RSS of each child is its own (``os.wait4``'s resource
usage), the wall time is measured around it. A photo of 1 x 168 pixels (PNG, no chart: exit 2)
is audited too. ``source`` adds the same audits with the ``fidelity`` package of another
checkout (before/after in one run), at the sizes ``source_sizes`` (an old audit of 108
megapixels needs about 15 GB). The mean ΔE00 of every audit is recorded, so that the answers
can be compared. Also writes ``memory.md`` (the table) and ``memory.png`` (the curve).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import REPO
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import run_process
from tests.fixtures.photos import photo, true_corners, write_image

ANCHOR = "a process that only decodes the JPEG with OpenImageIO (the same photo)"
PARAMETERS = {
    "sizes": Parameter("1,8,24,108", "photo sizes in megapixels (4:3), comma-separated"),
    "fill": Parameter(0.9, "chart width as a fraction of the photo's (0.9: fills it)"),
    "source": Parameter(None, "another checkout whose fidelity package is audited too (before)"),
    "source_sizes": Parameter("1,8,24", "sizes at which source is audited"),
    "label": Parameter("before", "name of source's runs")}
QUICK = {"sizes": "1"}
ARTEFACTS = "reports/benchmarks"

_DECODE = (
    "import sys, OpenImageIO as oiio\n"
    "inp = oiio.ImageInput.open(sys.argv[1])\n"
    "data = inp.read_image(0, 0, 0, 3, 'uint8')\n"
    "inp.close()\n"
    "print(data.shape, data.dtype)\n"
)


def audit(source: Path, image: Path, out: Path, corners: np.ndarray | None = None
          ) -> dict[str, Any]:
    """A whole ``fidelity audit`` process with the package of ``source``."""
    env = dict(os.environ, PYTHONPATH=str(source))
    args = [sys.executable, "-m", "fidelity", "audit", str(image), "--json", str(out)]
    if corners is not None:
        args += ["--corners", ",".join(f"{v:.1f}" for v in corners.ravel())]
    if out.exists():
        out.unlink()
    row = run_process(args, env, cwd=source, digits=3)  # python -m puts the working folder first
    if row["exit"] == 0:
        row["mean_delta_e"] = json.loads(out.read_text(encoding="utf-8"))["mean_delta_e"]
    return row


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Max RSS against megapixels, one line per process kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=100)
    kinds = sorted({r["process"] for r in rows if r["megapixels"] >= 1})
    for kind in kinds:
        pts = sorted((r["megapixels"], r["max_rss_mb"]) for r in rows
                     if r["process"] == kind and r["megapixels"] >= 1 and r["exit"] in (0, 2))
        if pts:
            ax.plot(*zip(*pts, strict=True), marker="o", label=kind)
    ax.axhline(1000, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("megapixels (JPEG, chart in the frame)")
    ax.set_ylabel("max RSS of the process (MB)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def table(rows: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table, with each process's ratio to the decoder of its photo."""
    anchor = {r["image"]: r for r in rows if r["process"] == "decode (anchor)"}
    lines = ["| image | MP | process | exit | max RSS MB | x decode | s | x decode | "
             "mean ΔE00 |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        a = anchor.get(r["image"])
        rss_x = f"{r['max_rss_mb'] / a['max_rss_mb']:.2f}" if a else ""
        s_x = f"{r['seconds'] / a['seconds']:.2f}" if a else ""
        de = f"{r['mean_delta_e']:.6f}" if "mean_delta_e" in r else ""
        lines.append(f"| {r['image']} | {r['megapixels']:g} | {r['process']} | {r['exit']} | "
                     f"{r['max_rss_mb']:.0f} | {rss_x} | {r['seconds']:.2f} | {s_x} | {de} |")
    return "\n".join(lines) + "\n"


def measure(ctx: Context) -> dict[str, Any]:
    fill, label = ctx["fill"], ctx["label"]
    source = Path(ctx["source"]) if ctx["source"] else None
    sizes = [float(s) for s in ctx["sizes"].split(",") if s.strip()]
    source_sizes = {float(s) for s in ctx["source_sizes"].split(",") if s.strip()}
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-memory-") as tmp:
        folder = Path(tmp)
        report = folder / "report.json"
        thin = folder / "thin-1x168.png"
        write_image(thin, np.full((168, 1, 3), 128, np.uint8))
        jobs: list[tuple[str, float, Path, np.ndarray | None]] = []
        for mp in sizes:
            width = int(round((mp * 1e6 * 4 / 3) ** 0.5))
            height = int(round(width * 3 / 4))
            jobs.append((f"{width}x{height}", width * height / 1e6,
                         folder / f"photo-{width}x{height}.jpg",
                         true_corners(width, height, fill)))
        jobs.append(("1x168 PNG", 168 / 1e6, thin, None))
        for name, mp, path, corners in jobs:
            if corners is not None:
                height, width = (int(v) for v in reversed(name.split("x")))
                write_image(path, photo(width, height, fill=fill))
            runs: list[tuple[str, Any]] = [("decode (anchor)", None)]
            runs += [("audit", (REPO, None))]
            if corners is not None:
                runs += [("audit --corners", (REPO, corners))]
            if source is not None and (mp in source_sizes or corners is None
                                       or round(mp) in source_sizes):
                runs += [(f"audit ({label})", (source, None))]
                if corners is not None:
                    runs += [(f"audit --corners ({label})", (source, corners))]
            for process, spec in runs:
                if spec is None:
                    row = run_process([sys.executable, "-c", _DECODE, str(path)])
                else:
                    row = audit(spec[0], path, report, spec[1])
                row = {"image": name, "megapixels": round(mp, 6), "process": process, **row}
                if corners is not None and "mean_delta_e" in row:
                    truth = true_corners(*(int(v) for v in name.split("x")), fill)
                    row["corners_given"] = process.startswith("audit --corners")
                    row["true_corners"] = truth.tolist()
                rows.append(row)
                ctx.log(f"{name:>12s} {process:>24s} exit {row['exit']} max RSS "
                        f"{row['max_rss_mb']:.0f} MB {row['seconds']:.2f} s")
            if path != thin:
                path.unlink()
    by_image: dict[str, list[float]] = {}
    for r in rows:
        if "mean_delta_e" in r:
            by_image.setdefault(r["image"], []).append(r["mean_delta_e"])
    spread = max((max(v) - min(v) for v in by_image.values()), default=0.0)
    return {"benchmark": "audit memory and time, whole processes, beside the decoder",
            "fill": fill, "source": str(source) if source else None, "label": label,
            "rows": rows, "mean_delta_e_largest_difference_per_image": spread}


def cases(details: dict[str, Any]) -> list[Case]:
    anchors = {r["image"]: r for r in details["rows"] if r["process"] == "decode (anchor)"}

    def fig(r: dict[str, Any]) -> Any:
        return figures(f"{r['process']}, {r['image']}", r["seconds"], cpu_s=r.get("cpu_seconds"),
                       max_rss_mb=r["max_rss_mb"], exit=r["exit"])

    return [case(f"{r['process']}, {r['image']} ({r['megapixels']:g} MP)", fig(r),
                 fig(anchors[r["image"]]) if r["image"] in anchors else None, per="process",
                 statistic="one process", process=True)
            for r in details["rows"] if r["process"] != "decode (anchor)"]


def report(result: dict[str, Any], folder: Path) -> None:
    """``memory.md`` (the table) and ``memory.png`` (max RSS against megapixels)."""
    rows = result["details"]["rows"]
    spread = result["details"]["mean_delta_e_largest_difference_per_image"]
    audits = sum("mean_delta_e" in r for r in rows)
    (folder / "memory.md").write_text(
        f"# Audit memory (max RSS) and time, whole processes\n\n{table(rows)}\n"
        f"Largest difference of the mean ΔE00 between the processes of one image: "
        f"{spread:.3g} ({audits} audits).\n", encoding="utf-8")
    plot(rows, folder / "memory.png")
