"""Benchmark: peak memory of an audit per megapixel, and its time, for large photos.

A synthetic photo of each size (a 4 x 6 ColorChecker filling a quarter of the frame's width on
a textured grey background, 8-bit JPEG, quality 90) is audited (``fidelity.check.audit_image``:
read, find the chart, measure, predict) in a fresh subprocess per size. The subprocess first
audits a small photo so that every library is loaded, then the large one; its peak resident
memory (``resource.getrusage(RUSAGE_SELF).ru_maxrss``) after the large audit minus the peak
after the small one is the memory the large image cost. Divided by the image's megapixels it is
the memory per megapixel, to compare with the decoded image itself (float32 RGB: 12 MB per
megapixel).

``--source DIR`` audits with the ``fidelity`` package found in DIR instead (an older checkout,
for a before/after comparison in the same run). Writes reports/benchmarks/memory.json (or
``--out``).  Run:  python -m benchmarks.bench_memory [--sizes 6,12,24] [--source DIR]
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Bytes per pixel of the decoded image an audit works on (float32 R, G, B).
DECODED_BYTES_PER_PIXEL = 12

_CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[1])
import fidelity
from fidelity.check import audit_image
kwargs = {}
import inspect
from fidelity.chart import image as _image
if "max_pixels" in inspect.signature(_image.read_image).parameters:
    import os
    os.environ["FIDELITY_MAX_PIXELS"] = str(10**10)
audit_image(sys.argv[2])
warm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
report = audit_image(sys.argv[3])
seconds = time.perf_counter() - t
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"fidelity": fidelity.__file__, "warm_kib": warm, "peak_kib": peak,
                  "seconds": seconds, "mean_delta_e": report.mean_delta_e}))
"""


def photo(width: int, height: int, seed: int = 0) -> np.ndarray:
    """An (H, W, 3) uint8 sRGB photo: the SAFE-COLOR chart (black frame, square patches, a
    quarter of the width) on a grey background with a smooth gradient and noise."""
    from fidelity.colour.charts import load_chart

    rng = np.random.default_rng(seed)
    y = np.linspace(0.35, 0.55, height, dtype=np.float32)[:, None]
    x = np.linspace(0.0, 0.1, width, dtype=np.float32)[None, :]
    base = ((y + x) * 255).astype(np.uint8)
    img = np.repeat(base[:, :, None], 3, axis=2)
    img += rng.integers(0, 6, size=(height, 1, 1), dtype=np.uint8)  # cheap texture
    srgb = np.round(load_chart().srgb * 255).astype(np.uint8)
    pitch = max(width // 4 // 6, 8)
    patch, gap = int(pitch * 0.8), pitch - int(pitch * 0.8)
    x0, y0 = width // 3, height // 3
    img[y0 - gap:y0 + 4 * pitch, x0 - gap:x0 + 6 * pitch] = 20
    for k in range(24):
        r, c = divmod(k, 6)
        ys, xs = y0 + r * pitch, x0 + c * pitch
        img[ys:ys + patch, xs:xs + patch] = srgb[k]
    return img


def write_jpeg(path: Path, img: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.UINT8)
    spec.attribute("Compression", "jpeg:90")
    if out is None or not out.open(str(path), spec):
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(img)
    out.close()


def measure(source: Path, small: Path, large: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(source))
    res = subprocess.run([sys.executable, "-c", _CHILD, str(source), str(small), str(large)],
                         capture_output=True, text=True, env=env, check=False)
    if res.returncode:
        raise RuntimeError(res.stderr[-2000:])
    out: dict[str, float] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def main() -> int:
    from benchmarks.machine import machine_info
    from fidelity.fileio import write_json_atomic

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="6,12,24",
                    help="Photo sizes in megapixels (4:3), comma-separated.")
    ap.add_argument("--source", type=Path, default=ROOT,
                    help="Checkout whose fidelity package is measured (default: this one).")
    ap.add_argument("--label", default=None, help="Name of this run in the JSON (default: "
                    "the source folder's name).")
    ap.add_argument("--out", type=Path, default=ROOT / "reports/benchmarks/memory.json")
    args = ap.parse_args()
    sizes = [float(s) for s in args.sizes.split(",") if s.strip()]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        small = Path(tmp) / "small.jpg"
        write_jpeg(small, photo(640, 480))
        print(f"{'image':>12s} {'MP':>6s} {'peak MB':>8s} {'MB/MP':>6s} {'x decoded':>9s} "
              f"{'s':>6s}")
        for mp in sizes:
            width = int(round((mp * 1e6 * 4 / 3) ** 0.5))
            height = int(round(width * 3 / 4))
            large = Path(tmp) / f"photo-{width}x{height}.jpg"
            write_jpeg(large, photo(width, height))
            m = measure(args.source, small, large)
            megapixels = width * height / 1e6
            extra_mb = (m["peak_kib"] - m["warm_kib"]) * 1024 / 1e6
            per_mp = extra_mb / megapixels
            rows.append({"image": f"{width}x{height}", "megapixels": round(megapixels, 3),
                         "peak_mb_above_warm": round(extra_mb, 1),
                         "mb_per_megapixel": round(per_mp, 2),
                         "times_decoded_image": round(per_mp / DECODED_BYTES_PER_PIXEL, 2),
                         "seconds": round(m["seconds"], 2),
                         "mean_delta_e": round(m["mean_delta_e"], 4)})
            print(f"{width:>5d}x{height:<6d} {megapixels:6.1f} {extra_mb:8.0f} {per_mp:6.1f} "
                  f"{per_mp / DECODED_BYTES_PER_PIXEL:9.2f} {m['seconds']:6.1f}")
            large.unlink()
    label = args.label or args.source.resolve().name
    doc = {}
    if args.out.is_file():
        doc = json.loads(args.out.read_text(encoding="utf-8"))
    doc.setdefault("runs", {})[label] = {
        "source": str(args.source), "date": time.strftime("%Y-%m-%d"), "rows": rows,
        "machine": machine_info()}
    doc["method"] = (__doc__ or "").split("\n\n")[1].replace("\n", " ")
    write_json_atomic(args.out, doc)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
