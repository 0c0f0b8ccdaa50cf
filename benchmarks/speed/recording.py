"""Auditing one frame of a 1 GB robot recording, against auditing the same frame as a PNG file.

A recording of about 1 GB (``gigabytes``) is written in /tmp (not in the repository) with
rosbags' writers for each kind: a ROS 1 bag, a ROS 2 bag with sqlite3 storage and a ROS 2 bag
with MCAP storage; its one topic holds 640 x 480 rgb8 sensor_msgs/Image frames of a chart
photo (the frames differ by a little noise), 30 per second. Each measurement is a whole
process, ``python -m fidelity audit RECORDING --topic /camera/image_raw --frame N`` (the chart
found, measured, predicted), run right after the anchor's process (``repeat`` pairs; medians),
timed from start to exit (wall seconds), with its peak resident
memory (``ru_maxrss`` of that child, from ``os.wait4``) and the bytes it read through read()
calls (``rchar`` of /proc/self/io at exit: page-cache hits included, so it counts what the
process asked for whatever the cache holds). The anchor, measured in the same run, is the same
audit of the same frame stored as a PNG file. Frames at the start, middle and end of the
recording are read: reading through the bag would make the late frames cost more and read
about the whole bag; using its index, every frame costs about the same and reads a few MB
beyond what the PNG audit reads (Python, numpy and the libraries themselves). The frame read
alone (``fidelity.chart.recording.read_frame`` in a warm process: index and message, median of
5) is timed too, with the bytes it reads.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from benchmarks.machine import REPO as ROOT
from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter

ANCHOR = "auditing the same frame stored as a PNG file, whole processes in pairs"
PARAMETERS = {"gigabytes": Parameter(1.0, "size of each recording"),
              "kinds": Parameter("ros1,sqlite3,mcap", "kinds of recording"),
              "repeat": Parameter(3, "pairs of runs per measurement (medians)")}
QUICK = {"gigabytes": 0.02, "repeat": 1}
NEEDS = ("rosbags",)
TOPIC = "/camera/image_raw"
WIDTH, HEIGHT = 640, 480
T0 = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333

_CHILD = r"""
import atexit, json, sys

def _report():
    with open("/proc/self/io") as f:
        io = dict(line.split(":") for line in f)
    sys.stderr.write("\nBENCH " + json.dumps({"rchar": int(io["rchar"])}) + "\n")

atexit.register(_report)
from fidelity.cli import main
main(sys.argv[1:], prog_name="fidelity")
"""


_READ_CHILD = r"""
import json, statistics, sys, time
from fidelity.chart.recording import Choice, read_frame

def rchar():
    with open("/proc/self/io") as f:
        return int(next(ln for ln in f if ln.startswith("rchar:")).split()[1])

path, picks, repeat = sys.argv[1], json.loads(sys.argv[2]), int(sys.argv[3])
read_frame(path, Choice(sys.argv[4], frame=0))  # imports done, the file's pages cached
out = {}
for name, k in picks.items():
    walls, reads = [], []
    for _ in range(repeat):
        before, t = rchar(), time.perf_counter()
        image, _ = read_frame(path, Choice(sys.argv[4], frame=k))
        walls.append(time.perf_counter() - t)
        reads.append(rchar() - before)
        assert image.recording.frame == k
    out[name] = {"seconds": statistics.median(walls), "read_bytes": max(reads)}
print(json.dumps(out))
"""


def read_only(path: Path, picks: dict[str, int], repeat: int) -> dict[str, Any]:
    """:func:`fidelity.chart.recording.read_frame` alone in a warm process: median seconds and
    bytes read (``rchar``) per frame read."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    res = subprocess.run([sys.executable, "-c", _READ_CHILD, str(path), json.dumps(picks),
                          str(repeat), TOPIC], env=env, capture_output=True, text=True,
                         check=True)
    out: dict[str, Any] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def frames(n: int) -> list[np.ndarray]:
    """``n`` distinct 640 x 480 photos of the chart (the same chart, different noise)."""
    from tests.fixtures.photos import photo

    base = photo(WIDTH, HEIGHT).astype(np.int16)
    rng = np.random.default_rng(0)
    return [np.clip(base + rng.integers(-2, 3, base.shape), 0, 255).astype(np.uint8)
            for _ in range(n)]


def write(path: Path, kind: str, count: int, images: list[np.ndarray]) -> Path:
    """A recording of ``kind`` (ros1, sqlite3, mcap) of ``count`` frames cycling ``images``."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types = ts.types
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    msgtype = "sensor_msgs/msg/Image"
    writer: Any = (Writer1(path) if ros1 else Writer2(
        path, version=9,
        storage_plugin=StoragePlugin.SQLITE3 if kind == "sqlite3" else StoragePlugin.MCAP))
    payloads = []
    for img in images:
        stamp = types["builtin_interfaces/msg/Time"](sec=0, nanosec=0)
        head = (types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="camera") if ros1
                else types["std_msgs/msg/Header"](stamp=stamp, frame_id="camera"))
        msg = types[msgtype](header=head, height=HEIGHT, width=WIDTH, encoding="rgb8",
                             is_bigendian=0, step=WIDTH * 3, data=img.reshape(-1))
        payloads.append(serialize(msg, msgtype))
    with writer:
        conn = writer.add_connection(TOPIC, msgtype, typestore=ts)
        for k in range(count):
            writer.write(conn, T0 + k * PERIOD_NS, payloads[k % len(payloads)])
    return path


def size_of(path: Path) -> int:
    return sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir()))


def run(args: list[str]) -> dict[str, float]:
    """One whole ``fidelity`` process: wall seconds, peak RSS (MB, its own:
    :func:`run_process`'s launcher), bytes read (MB)."""
    from benchmarks.speed.timing import run_process

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    row = run_process([sys.executable, "-c", _CHILD, *args], env=env, digits=4)
    if row["exit"]:
        raise RuntimeError(f"{args}: exit {row['exit']}: {row['stderr']}")
    line = row["stderr"]  # the child's last line: its bytes read, written at exit
    if not line.startswith("BENCH "):
        raise RuntimeError(f"{args}: no BENCH line at the end of stderr: {line!r}")
    rchar = json.loads(line[6:])["rchar"]
    return {"wall_s": row["seconds"], "max_rss_mb": row["max_rss_mb"], "read_mb": rchar / 1e6}


def pairs(bag_args: list[str], png_args: list[str], repeat: int) -> dict[str, Any]:
    """``repeat`` runs of the recording's audit, each right after the anchor's (so that a
    change of the machine's load touches both): medians of each, the median of the pairs'
    wall-time ratios, and the peak RSS and bytes read of the median runs."""
    bag, png = [], []
    for _ in range(repeat):
        png.append(run(png_args))
        bag.append(run(bag_args))
    ratios = sorted(b["wall_s"] / a["wall_s"] for a, b in zip(png, bag, strict=True))

    def median(rows: list[dict[str, float]]) -> dict[str, float]:
        return sorted(rows, key=lambda r: r["wall_s"])[len(rows) // 2]

    return {"bag": median(bag), "png": median(png), "wall_ratio": statistics.median(ratios),
            "bag_wall_s_runs": [round(r["wall_s"], 3) for r in bag],
            "png_wall_s_runs": [round(r["wall_s"], 3) for r in png]}


def measure(ctx: Context) -> dict[str, Any]:
    from fidelity.chart.image import write_png

    args = SimpleNamespace(**ctx.params)
    frame_bytes = WIDTH * HEIGHT * 3
    count = int(args.gigabytes * 1e9 // frame_bytes)
    images = frames(8)
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-recording-", dir="/tmp") as tmp:
        folder = Path(tmp)
        picks = {"first": 0, "middle": count // 2, "last": count - 1}
        pngs = {}
        for name, k in picks.items():
            pngs[name] = folder / f"frame-{name}.png"
            write_png(pngs[name], images[k % len(images)] / 255.0, 8)
        for kind in [k.strip() for k in args.kinds.split(",") if k.strip()]:
            t = time.perf_counter()
            path = write(folder / (f"drive-{kind}.bag" if kind == "ros1" else f"drive-{kind}"),
                         kind, count, images)
            written_s = time.perf_counter() - t
            size = size_of(path)
            alone = read_only(path, picks, 5)
            for name, k in picks.items():
                m = pairs(["audit", str(path), "--topic", TOPIC, "--frame", str(k), "-q"],
                          ["audit", str(pngs[name]), "-q"], args.repeat)
                got, anchor = m["bag"], m["png"]
                row = {
                    "recording": kind, "gigabytes": round(size / 1e9, 3), "frames": count,
                    "frame": k, "position": name, "write_s": round(written_s, 1),
                    "wall_s": round(got["wall_s"], 3), "wall_s_runs": m["bag_wall_s_runs"],
                    "max_rss_mb": round(got["max_rss_mb"], 1),
                    "read_mb": round(got["read_mb"], 1),
                    "png_wall_s": round(anchor["wall_s"], 3),
                    "png_wall_s_runs": m["png_wall_s_runs"],
                    "png_max_rss_mb": round(anchor["max_rss_mb"], 1),
                    "png_read_mb": round(anchor["read_mb"], 1),
                    "wall_ratio": round(m["wall_ratio"], 3),
                    "rss_ratio": round(got["max_rss_mb"] / anchor["max_rss_mb"], 3),
                    "read_beyond_png_mb": round(got["read_mb"] - anchor["read_mb"], 1),
                    "read_fraction_of_recording": round(
                        (got["read_mb"] - anchor["read_mb"]) * 1e6 / size, 5),
                    "read_frame_s": round(alone[name]["seconds"], 4),
                    "read_frame_mb": round(alone[name]["read_bytes"] / 1e6, 3),
                }
                rows.append(row)
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    return {"repeat": args.repeat, "rows": rows,
            "summary": {
                "median_wall_ratio": statistics.median(r["wall_ratio"] for r in rows),
                "max_wall_ratio": max(r["wall_ratio"] for r in rows),
                "max_rss_ratio": max(r["rss_ratio"] for r in rows),
                "max_read_beyond_png_mb": max(r["read_beyond_png_mb"] for r in rows),
                "max_read_frame_s": max(r["read_frame_s"] for r in rows),
                "max_read_frame_mb": max(r["read_frame_mb"] for r in rows),
                "median_wall_s": statistics.median(r["wall_s"] for r in rows)}}


def cases(details: dict[str, Any]) -> list[Case]:
    out = []
    for r in details["rows"]:
        n = len(r["wall_s_runs"])
        out.append(case(
            f"{r['recording']}, {r['position']} frame ({r['frame']} of {r['frames']}, "
            f"{r['gigabytes']:g} GB)",
            figures(f"fidelity audit {r['recording']} recording --frame {r['frame']}",
                    r["wall_s"], max_rss_mb=r["max_rss_mb"], read_mb=r["read_mb"],
                    runs_s=r["wall_s_runs"]),
            figures("fidelity audit of the frame as a PNG", r["png_wall_s"],
                    max_rss_mb=r["png_max_rss_mb"], read_mb=r["png_read_mb"],
                    runs_s=r["png_wall_s_runs"]),
            per="process", statistic=f"median of {n} processes, each right after the anchor's",
            process=True, wall=r["wall_ratio"], of="median of the pairs' wall-time ratios",
            note=(f"the frame read alone (warm process): {r['read_frame_s']} s, "
                  f"{r['read_frame_mb']} MB")))
    return out
