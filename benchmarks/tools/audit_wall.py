"""Whole-process wall time and max RSS of ``fidelity audit`` on large JPEGs, this checkout
against another source tree (``--before``), beside OpenCV mcc's ``process`` on the 12 MP file
(issue 59). The images: the chart render (``fidelity render --pixels-per-patch 48``) resized to
4000 x 3000 and 12000 x 9000 (``cv2.INTER_LINEAR``), JPEG quality 92. Rounds interleaved;
medians printed.

    python -m benchmarks.tools.audit_wall --before /tmp/before --repeats 3
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from tests.fixtures.processes import run_process

REPO = Path(__file__).resolve().parents[2]
SIZES = {"12 MP": (4000, 3000), "108 MP": (12000, 9000)}
MCC = ("import sys, cv2\n"
       "img = cv2.imread(sys.argv[1])\n"
       "d = cv2.mcc.CCheckerDetector_create()\n"
       "ok = d.process(img, cv2.mcc.MCC24, 1)\n"
       "print(len(d.getListColorChecker()) if ok else 0)\n")


def make_images(folder: Path) -> dict[str, Path]:
    """The chart render resized to each of :data:`SIZES`, quality-92 JPEGs."""
    import cv2

    subprocess.run([sys.executable, "-m", "fidelity", "render", "--pixels-per-patch", "48",
                    "--out", str(folder / "render"), "-q"], check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=str(REPO)))
    src = cv2.imread(str(folder / "render" / "developed.png"), cv2.IMREAD_COLOR)
    out = {}
    for name, (w, h) in SIZES.items():
        path = folder / f"{name.replace(' ', '')}.jpg"
        cv2.imwrite(str(path), cv2.resize(src, (w, h), interpolation=cv2.INTER_LINEAR),
                    [cv2.IMWRITE_JPEG_QUALITY, 92])
        out[name] = path
    return out


def run(cmd: list[str], pythonpath: str, cwd: str) -> tuple[float, float]:
    """Wall seconds and max RSS (MB, the process's own) of one whole process
    (:func:`tests.fixtures.processes.run_process`)."""
    got = run_process(cmd, env=dict(os.environ, PYTHONPATH=pythonpath), cwd=Path(cwd))
    if got["exit"] not in (0, 1):
        raise RuntimeError(f"{cmd} failed: {got['stderr']}")
    return float(got["seconds"]), float(got["max_rss_mb"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, default=None)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        images = make_images(Path(tmp))
        trees = {"after": str(REPO)} | ({"before": str(args.before)} if args.before else {})
        cmds: dict[str, tuple[list[str], str]] = {}
        for name, image in images.items():
            for label, tree in trees.items():
                cmds[f"audit {name} ({label})"] = (
                    [sys.executable, "-m", "fidelity", "audit", str(image), "-q", "--json",
                     str(Path(tmp) / "a.json")], tree)
        cmds["OpenCV mcc process 12 MP"] = ([sys.executable, "-c", MCC, str(images["12 MP"])],
                                            str(REPO))
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in cmds}
        for _ in range(args.repeats):
            for name, (cmd, tree) in cmds.items():
                times[name].append(run(cmd, tree, tmp))
    print("| process | median wall s | median max RSS MB | runs |")
    print("|---|---|---|---|")
    for name, ts in times.items():
        print(f"| {name} | {statistics.median(t for t, _ in ts):.2f} | "
              f"{statistics.median(m for _, m in ts):.0f} | "
              f"{', '.join(f'{t:.2f}' for t, _ in ts)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
