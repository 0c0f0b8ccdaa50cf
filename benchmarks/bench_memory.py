"""Benchmark: peak memory (max RSS) and wall time of whole ``fidelity audit`` processes, per
megapixel, beside the image decoder alone (the anchor).

For each size (megapixels, 4:3) a synthetic photo is written as an 8-bit sRGB JPEG (quality
90) in a temporary folder: the 4 x 6 ColorChecker drawn square to the frame on a grey
gradient, its patch pitch ``--fill`` of the width divided by 6 (0.9: the chart fills the
frame, the largest sampling windows; 0.25: a chart in a scene). Then, one fresh process each,
one after the other in the same run:

``decode`` (the anchor)
    a Python process that imports OpenImageIO and decodes the JPEG into a ``uint8`` NumPy
    array, what any tool that reads the photo must hold;
``audit``
    ``python -m fidelity audit PHOTO --json F``: read, find the chart, measure, predict;
``audit --corners``
    the same with the chart's four corner-patch centres given (from the drawing).

The max RSS of each child is its own (``os.wait4``'s resource usage), the wall time is measured
around it. A photo of 1 x 168 pixels (PNG, no chart: exit 2) is audited too. ``--source DIR``
adds the same audits with the ``fidelity`` package of another checkout (before/after in one
run), at the sizes ``--source-sizes`` (an old audit of 108 megapixels needs about 15 GB). The
mean ΔE00 of every audit is recorded, so that the answers can be compared.

Writes reports/benchmarks/memory.json, memory.md (the table) and memory.png (the curve), or
under ``--out``. Run:  python -m benchmarks.bench_memory [--sizes 1,8,24,108]
[--source /work/main --source-sizes 1,8,24]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

_DECODE = (
    "import sys, OpenImageIO as oiio\n"
    "inp = oiio.ImageInput.open(sys.argv[1])\n"
    "data = inp.read_image(0, 0, 0, 3, 'uint8')\n"
    "inp.close()\n"
    "print(data.shape, data.dtype)\n"
)


def chart_geometry(width: int, height: int, fill: float) -> tuple[int, int, int, int]:
    """``(x0, y0, pitch, patch)`` of the chart :func:`photo` draws: top-left of the dark skin
    patch, patch pitch and patch side in pixels."""
    pitch = max(int(width * fill) // 6, 8)
    patch = int(pitch * 0.8)
    x0 = (width - 6 * pitch) // 2 if fill > 0.5 else width // 3
    y0 = (height - 4 * pitch) // 2 if fill > 0.5 else height // 3
    return x0, y0, pitch, patch


def true_corners(width: int, height: int, fill: float = 0.25) -> np.ndarray:
    """``(4, 2)`` centres of the dark skin, bluish green, black and white patches of
    :func:`photo`'s chart."""
    x0, y0, pitch, patch = chart_geometry(width, height, fill)
    c = (patch - 1) / 2.0
    cells = [(0, 0), (5, 0), (5, 3), (0, 3)]
    return np.array([[x0 + u * pitch + c, y0 + v * pitch + c] for u, v in cells], float)


def photo(width: int, height: int, seed: int = 0, fill: float = 0.25) -> np.ndarray:
    """An (H, W, 3) uint8 sRGB photo: the SAFE-COLOR chart (black frame, square patches, a
    pitch of ``fill`` x width / 6) on a grey background with a smooth gradient and noise."""
    from fidelity.colour.charts import load_chart

    rng = np.random.default_rng(seed)
    y = np.linspace(0.35, 0.55, height, dtype=np.float32)[:, None]
    x = np.linspace(0.0, 0.1, width, dtype=np.float32)[None, :]
    base = ((y + x) * 255).astype(np.uint8)
    img = np.repeat(base[:, :, None], 3, axis=2)
    img += rng.integers(0, 6, size=(height, 1, 1), dtype=np.uint8)  # cheap texture
    srgb = np.round(load_chart().srgb * 255).astype(np.uint8)
    x0, y0, pitch, patch = chart_geometry(width, height, fill)
    gap = pitch - patch
    img[max(y0 - gap, 0):y0 + 4 * pitch, max(x0 - gap, 0):x0 + 6 * pitch] = 20
    for k in range(24):
        r, c = divmod(k, 6)
        ys, xs = y0 + r * pitch, x0 + c * pitch
        img[ys:ys + patch, xs:xs + patch] = srgb[k]
    return img


def write_image(path: Path, img: np.ndarray) -> None:
    """Write uint8 RGB as JPEG (quality 90) or PNG, by the path's suffix."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.UINT8)
    spec.attribute("Compression", "jpeg:90")
    if out is None or not out.open(str(path), spec):
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(np.ascontiguousarray(img))
    out.close()


write_jpeg = write_image


#: A small launcher that runs the measured command as its own child and reports that child's
#: resource usage: Linux carries a process's peak RSS over fork and exec, so a child started
#: straight from this (large) benchmark process would report this process's peak as its own.
_LAUNCH = (
    "import json, os, sys, time\n"
    "t = time.perf_counter()\n"
    "pid = os.fork()\n"
    "if pid == 0:\n"
    "    null = os.open(os.devnull, os.O_WRONLY)\n"
    "    os.dup2(null, 1)\n"
    "    os.execv(sys.argv[1], sys.argv[1:])\n"
    "_, status, usage = os.wait4(pid, 0)\n"
    "print(json.dumps({'exit': os.waitstatus_to_exitcode(status),\n"
    "                  'seconds': time.perf_counter() - t,\n"
    "                  'cpu_seconds': usage.ru_utime + usage.ru_stime,\n"
    "                  'max_rss_kib': usage.ru_maxrss}))\n"
)


def run_process(args: list[str], env: dict[str, str] | None = None,
                cwd: Path | None = None) -> dict[str, Any]:
    """Run one process (through :data:`_LAUNCH`); its exit code, wall seconds, CPU seconds
    (user and system, with the children it waited for), max RSS (MB, its own) and the last line
    it wrote to stderr."""
    res = subprocess.run([sys.executable, "-S", "-c", _LAUNCH, *args], capture_output=True,
                         text=True, env=env, cwd=cwd, check=False)
    if res.returncode or not res.stdout.strip():
        raise RuntimeError(f"launcher failed: {res.stderr[-2000:]}")
    usage = json.loads(res.stdout.strip().splitlines()[-1])
    err = res.stderr.strip()
    return {"exit": usage["exit"], "seconds": round(usage["seconds"], 2),
            "cpu_seconds": round(usage["cpu_seconds"], 2),
            "max_rss_mb": round(usage["max_rss_kib"] * 1024 / 1e6, 1),
            "stderr": err.splitlines()[-1] if err else ""}


def audit(source: Path, image: Path, out: Path, corners: np.ndarray | None = None
          ) -> dict[str, Any]:
    """A whole ``fidelity audit`` process with the package of ``source``."""
    env = dict(os.environ, PYTHONPATH=str(source))
    args = [sys.executable, "-m", "fidelity", "audit", str(image), "--json", str(out)]
    if corners is not None:
        args += ["--corners", ",".join(f"{v:.1f}" for v in corners.ravel())]
    if out.exists():
        out.unlink()
    row = run_process(args, env, cwd=source)  # python -m puts the working folder first
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


def main() -> int:
    from benchmarks.machine import machine_info
    from fidelity.core.fileio import write_json_atomic

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="1,8,24,108",
                    help="Photo sizes in megapixels (4:3), comma-separated.")
    ap.add_argument("--fill", type=float, default=0.9,
                    help="Chart width as a fraction of the photo's (0.9: fills it).")
    ap.add_argument("--source", type=Path, default=None,
                    help="Another checkout whose fidelity package is audited too (before).")
    ap.add_argument("--source-sizes", default="1,8,24",
                    help="Sizes at which --source is audited (its memory may not allow more).")
    ap.add_argument("--label", default="before", help="Name of --source's runs.")
    ap.add_argument("--out", type=Path, default=ROOT / "reports/benchmarks")
    args = ap.parse_args()
    sizes = [float(s) for s in args.sizes.split(",") if s.strip()]
    source_sizes = {float(s) for s in args.source_sizes.split(",") if s.strip()}
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
                         true_corners(width, height, args.fill)))
        jobs.append(("1x168 PNG", 168 / 1e6, thin, None))
        print(f"{'image':>12s} {'process':>24s} {'exit':>4s} {'max RSS MB':>10s} {'s':>6s}")
        for name, mp, path, corners in jobs:
            if corners is not None:
                height, width = (int(v) for v in reversed(name.split("x")))
                write_image(path, photo(width, height, fill=args.fill))
            runs: list[tuple[str, Any]] = [("decode (anchor)", None)]
            runs += [("audit", (ROOT, None))]
            if corners is not None:
                runs += [("audit --corners", (ROOT, corners))]
            if args.source is not None and (mp in source_sizes or corners is None
                                            or round(mp) in source_sizes):
                runs += [(f"audit ({args.label})", (args.source, None))]
                if corners is not None:
                    runs += [(f"audit --corners ({args.label})", (args.source, corners))]
            for process, spec in runs:
                if spec is None:
                    row = run_process([sys.executable, "-c", _DECODE, str(path)])
                else:
                    row = audit(spec[0], path, report, spec[1])
                row = {"image": name, "megapixels": round(mp, 6), "process": process, **row}
                if corners is not None and "mean_delta_e" in row:
                    truth = true_corners(*(int(v) for v in name.split("x")), args.fill)
                    row["corners_given"] = process.startswith("audit --corners")
                    row["true_corners"] = truth.tolist()
                rows.append(row)
                print(f"{name:>12s} {process:>24s} {row['exit']:>4d} {row['max_rss_mb']:>10.0f} "
                      f"{row['seconds']:>6.2f}", flush=True)
            if path != thin:
                path.unlink()
    deltas = [r["mean_delta_e"] for r in rows if "mean_delta_e" in r]
    by_image: dict[str, list[float]] = {}
    for r in rows:
        if "mean_delta_e" in r:
            by_image.setdefault(r["image"], []).append(r["mean_delta_e"])
    spread = max((max(v) - min(v) for v in by_image.values()), default=0.0)
    doc = {
        "benchmark": "audit memory and time, whole processes, beside the decoder",
        "method": (__doc__ or "").split("\n\n")[1].replace("\n", " "),
        "date": time.strftime("%Y-%m-%d"), "fill": args.fill,
        "source": str(args.source) if args.source else None, "label": args.label,
        "rows": rows,
        "mean_delta_e_largest_difference_per_image": spread,
        "machine": machine_info(),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "memory.json", doc)
    (args.out / "memory.md").write_text(
        f"# Audit memory (max RSS) and time, whole processes\n\n{table(rows)}\n"
        f"Largest difference of the mean ΔE00 between the processes of one image: "
        f"{spread:.3g} ({len(deltas)} audits).\n", encoding="utf-8")
    plot(rows, args.out / "memory.png")
    print(f"mean ΔE00: largest difference between processes of one image {spread:.3g}")
    print(f"wrote {args.out / 'memory.json'}, memory.md, memory.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
