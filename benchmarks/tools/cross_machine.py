"""Do two machines give the same detections and the same ΔmAP? The same sweep cells (same code,
same library versions, same images and detector) run on two machines are compared image by
image (are the stored detections bit for bit the same?) and cell by cell (mAP and the ΔmAP
against each machine's own baseline). onnxruntime picks its kernels by the processor's
instruction set, so an int8 detector may compute differently on another processor.

Usage:
  python -m benchmarks.tools.cross_machine digest STORE OUT.json [--model M] [--cpu-here]
      (STORE: a sweep store's folder or its sqlite file)
      per-image digests (SHA-256 of the detections, 16 hex digits), the finished cells' mAP and
      the store's provenance; small enough to carry off a lent machine. --cpu-here: add this
      machine's processor and instructions to a store made here by a version that did not
      record them
  python -m benchmarks.tools.cross_machine compare A.json B.json [--out reports/coco/cross_machine]
      [--stores STORE_A STORE_B]
      --stores: where both stores are at hand, also how far apart the detections that are not
      bit for bit the same are (boxes in pixels, scores), cell by cell

  python -m benchmarks.tools.cross_machine rows A_TABLES.json B_TABLES.json --model M
      [--out reports/coco/cross_machine_rows_M]
      one detector's rows of two ``tables.json`` (every cell's mAP and ΔmAP with its SE, the
      baseline and the worst case per ΔE): a whole grid measured twice, where the stores are
      gone or too large to digest (A: e.g. ``git show REV:reports/coco/tables.json``)

benchmarks/tools/reproduction_sample.sh runs the same sample cells on any machine.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sqlite3
import statistics
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.machine import write_report


def _open(store: str | Path) -> sqlite3.Connection:
    """A sweep store, read only: its folder, or its ``sweep.sqlite`` (or a copy of it, as
    benchmarks/tools/reproduction_sample.sh brings back)."""
    path = Path(store)
    return sqlite3.connect(f"file:{path if path.is_file() else path / 'sweep.sqlite'}?mode=ro",
                           uri=True)


def digest_store(store: str | Path, model: str | None = None) -> dict[str, Any]:
    """Per-image detection digests, finished cells and provenance of a sweep store (read
    only)."""
    db = _open(store)
    models = [r[0] for r in db.execute("SELECT model FROM models")]
    model = model or models[0]
    meta = {k: json.loads(v) for k, v in db.execute("SELECT key, value FROM meta")}
    settings = json.loads(db.execute("SELECT settings FROM models WHERE model=?",
                                     (model,)).fetchone()[0])
    cells = [[t, g, n, m] for t, g, n, m in db.execute(
        "SELECT transform, target, images, map FROM cells WHERE model=? AND status='done'",
        (model,))]
    digests: dict[str, dict[str, str]] = {}
    for t, g, i, blob in db.execute(
            "SELECT transform, target, image_id, dets FROM detections WHERE model=?", (model,)):
        digests.setdefault(f"{t}:{g:g}", {})[str(i)] = \
            hashlib.sha256(zlib.decompress(blob)).hexdigest()[:16]
    db.close()
    return {"model": model, "machine": meta.get("machine"), "versions": meta.get("versions"),
            "settings": settings, "cells": cells, "digests": digests}


def detection_differences(a: dict[int, np.ndarray], b: dict[int, np.ndarray]
                          ) -> dict[str, Any]:
    """How far apart two runs' detections of one cell are (image id -> (n, 6) ``x1, y1, x2,
    y2, score, class``): over the images both hold, how many have as many detections of each
    class (``matched``), the largest difference of a box coordinate (pixels) and of a score
    among those, each detection paired with the other run's of its class whose box is nearest
    (largest coordinate difference, optimal assignment: two near-equal scores may swap the
    order), and how many images do not (``unmatched``)."""
    from scipy.optimize import linear_sum_assignment

    matched = unmatched = 0
    box = score = 0.0
    for i in sorted(set(a) & set(b)):
        da, db_ = a[i].astype(np.float64), b[i].astype(np.float64)
        if da.shape != db_.shape or not np.array_equal(np.sort(da[:, 5]), np.sort(db_[:, 5])):
            unmatched += 1
            continue
        matched += 1
        for c in np.unique(da[:, 5]):
            pa, pb = da[da[:, 5] == c], db_[db_[:, 5] == c]
            cost = np.abs(pa[:, None, :4] - pb[None, :, :4]).max(axis=2)
            r, k = linear_sum_assignment(cost)
            box = max(box, float(cost[r, k].max()))
            score = max(score, float(np.abs(pa[r, 4] - pb[k, 4]).max()))
    return {"matched": matched, "unmatched": unmatched, "max_box_px": box,
            "max_score": score}


def _store_detections(store: str | Path, model: str) -> dict[str, dict[int, np.ndarray]]:
    from fidelity.coco.store import unpack_detections

    db = _open(store)
    cells: dict[str, dict[int, np.ndarray]] = {}
    for t, g, i, blob in db.execute(
            "SELECT transform, target, image_id, dets FROM detections WHERE model=?", (model,)):
        cells.setdefault(f"{t}:{g:g}", {})[int(i)] = unpack_detections(blob)
    db.close()
    return cells


def store_differences(store_a: str | Path, store_b: str | Path, model: str
                      ) -> list[dict[str, Any]]:
    """:func:`detection_differences` of every cell both stores hold of ``model``."""
    a, b = _store_detections(store_a, model), _store_detections(store_b, model)
    return [{"cell": k, **detection_differences(a[k], b[k])} for k in sorted(set(a) & set(b))]


def _cell_maps(a: dict[str, Any], b: dict[str, Any]) -> tuple[dict[str, float],
                                                                dict[str, float]]:
    """The finished cells' mAP of each run, of the cells both finished on as many images
    (a run of fewer images scores other images)."""
    ma = {f"{t}:{g:g}": (n, m) for t, g, n, m in a["cells"] if m is not None}
    mb = {f"{t}:{g:g}": (n, m) for t, g, n, m in b["cells"] if m is not None}
    both = {k for k in set(ma) & set(mb) if ma[k][0] == mb[k][0]}
    return {k: ma[k][1] for k in both}, {k: mb[k][1] for k in both}


def _difference_stats(diffs: list[float]) -> dict[str, float | None]:
    """Mean, SD and largest magnitude of the B − A differences of ΔmAP (points)."""
    return {"loss_difference_mean": statistics.mean(diffs) if diffs else None,
            "loss_difference_sd": statistics.stdev(diffs) if len(diffs) > 1 else None,
            "loss_difference_max_abs": max(map(abs, diffs)) if diffs else None}


def compare(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """Image- and cell-level agreement of two digest documents of the same model."""
    cells = []
    same = total = 0
    for key in sorted(set(a["digests"]) & set(b["digests"])):
        da, db_ = a["digests"][key], b["digests"][key]
        common = sorted(set(da) & set(db_))
        eq = sum(da[i] == db_[i] for i in common)
        same += eq
        total += len(common)
        cells.append({"cell": key, "images": len(common), "identical": eq})
    ma, mb = _cell_maps(a, b)
    base = "baseline:0"
    rows: list[dict[str, Any]] = []
    if base in ma and base in mb:
        for key in sorted(set(ma) & set(mb) - {base}):
            la = 100 * (ma[base] - ma[key])
            lb = 100 * (mb[base] - mb[key])
            rows.append({"cell": key, "map_a": 100 * ma[key], "map_b": 100 * mb[key],
                         "loss_a": la, "loss_b": lb, "difference": lb - la})
    diffs: list[float] = [float(r["difference"]) for r in rows]
    summary = {
        "images_compared": total, "identical": same,
        "identical_fraction": same / total if total else None,
        "baseline_map_a": 100 * ma[base] if base in ma else None,
        "baseline_map_b": 100 * mb[base] if base in mb else None,
        "loss_cells": len(rows), **_difference_stats(diffs),
    }
    return {"summary": summary, "images": cells, "losses": rows}


def _machine_words(doc: dict[str, Any]) -> str:
    m = doc.get("machine") or {}
    ins = m.get("instructions")
    return (f"{m.get('cpu') or m.get('platform')}, {m.get('cpus')} CPUs"
            + (f", instructions {' '.join(ins)}" if ins else ""))


#: A version left out of the comparison: fidelity's own string says how it was installed
#: (``0.0.0+source`` from a checkout); the code is the commit both runs used.
_NOT_COMPARED = ("fidelity",)


def version_differences(a: dict[str, Any], b: dict[str, Any]) -> dict[str, list[Any]]:
    """The versions two runs computed with that differ (name -> [A's, B's]: Python and the
    libraries; None where one run lacks a library)."""
    va, vb = a.get("versions") or {}, b.get("versions") or {}
    return {k: [va.get(k), vb.get(k)] for k in sorted(set(va) | set(vb))
            if k not in _NOT_COMPARED and va.get(k) != vb.get(k)}


def _versions_words(a: dict[str, Any], b: dict[str, Any]) -> str:
    diff = version_differences(a, b)
    if not diff:
        return "same library versions"
    return "library versions differ: " + ", ".join(f"{k} {x} / {y}" for k, (x, y) in
                                                   diff.items())


def markdown(a: dict[str, Any], b: dict[str, Any], result: dict[str, Any]) -> str:
    s = result["summary"]
    lines = [
        f"# Same sweep cells in two runs: {a['model']}",
        "",
        "Written by `python -m benchmarks.tools.cross_machine compare A.json B.json` from the "
        "per-image digests `python -m benchmarks.tools.cross_machine digest STORE` made of each "
        f"run's store (same code, images and detector file; {_versions_words(a, b)}).",
        "",
        f"- A: {_machine_words(a)}; versions {json.dumps(a.get('versions'))}",
        f"- B: {_machine_words(b)}; versions {json.dumps(b.get('versions'))}",
        "",
        f"Images whose stored detections are bit for bit the same: {s['identical']} of "
        f"{s['images_compared']} ({100 * (s['identical_fraction'] or 0):.1f} %) over "
        f"{len(result['images'])} cells.",
    ]
    if s["baseline_map_a"] is not None and s["baseline_map_b"] is not None:
        lines += [
            "",
            f"Baseline mAP: A {s['baseline_map_a']:.3f}, B {s['baseline_map_b']:.3f} "
            f"(B − A {s['baseline_map_b'] - s['baseline_map_a']:+.3f} points).",
        ]
    if result["losses"]:
        lines += [
            "",
            f"ΔmAP (each machine against its own baseline) over {s['loss_cells']} cells: "
            f"B − A mean {s['loss_difference_mean']:+.3f} points, SD "
            f"{s['loss_difference_sd']:.3f}, largest |B − A| "
            f"{s['loss_difference_max_abs']:.3f}.",
            "",
            "| cell | mAP A | mAP B | ΔmAP A | ΔmAP B | B − A |",
            "|---|---:|---:|---:|---:|---:|",
        ]
        lines += [f"| {r['cell']} | {r['map_a']:.3f} | {r['map_b']:.3f} | {r['loss_a']:+.2f} | "
                  f"{r['loss_b']:+.2f} | {r['difference']:+.3f} |" for r in result["losses"]]
    lines += ["", "| cell | images | identical |", "|---|---:|---:|"]
    lines += [f"| {c['cell']} | {c['images']} | {c['identical']} "
              f"({100 * c['identical'] / c['images']:.1f} %) |"
              for c in result["images"] if c["images"]]
    if result.get("differences"):
        lines += ["", "How far apart the detections are, image by image: an image is matched when "
                  "both runs found as many detections of each class; each detection is paired "
                  "with the other run's of its class whose box is nearest; the largest "
                  "difference of a box coordinate (pixels) and of a score over the matched "
                  "images.", "",
                  "| cell | matched | unmatched | largest box difference (px) | "
                  "largest score difference |", "|---|---:|---:|---:|---:|"]
        lines += [f"| {d['cell']} | {d['matched']} | {d['unmatched']} | {d['max_box_px']:.2g} | "
                  f"{d['max_score']:.2g} |" for d in result["differences"]]
    return "\n".join(lines) + "\n"


def compare_rows(a: dict[str, Any], b: dict[str, Any], model: str) -> dict[str, Any]:
    """One detector's rows of two ``tables.json`` documents (``{"tables": ...}``): per cell
    done in both, mAP and ΔmAP (points) of each and B − A, also in units of B's standard
    error; the baseline; per ΔE the worst case of each (value and transform)."""
    ta, tb = a["tables"], b["tables"]

    def cells(t: dict[str, Any]) -> dict[str, dict[str, Any]]:
        return {f"{c['transform']}:{c['delta_e']:g}": c for c in t["cells"].get(model, ())
                if c.get("status") == "done" and c.get("dmap_points") is not None}

    ca, cb = cells(ta), cells(tb)
    rows: list[dict[str, Any]] = []
    for key in sorted(set(ca) & set(cb)):
        x, y = ca[key], cb[key]
        se = y.get("dmap_points_se")
        diff = y["dmap_points"] - x["dmap_points"]
        rows.append({"cell": key, "map_a": 100 * x["map"], "map_b": 100 * y["map"],
                     "loss_a": x["dmap_points"], "loss_b": y["dmap_points"], "difference": diff,
                     "se_b": se, "in_se": abs(diff) / se if se else None})
    wa = {w["delta_e"]: w for w in ta["worst_case"].get(model, ()) if w["delta_e"] > 0}
    wb = {w["delta_e"]: w for w in tb["worst_case"].get(model, ()) if w["delta_e"] > 0}
    worst = [{"delta_e": g, "transform_a": wa[g]["worst_transform"],
              "transform_b": wb[g]["worst_transform"], "loss_a": wa[g]["dmap_points"],
              "loss_b": wb[g]["dmap_points"],
              "difference": wb[g]["dmap_points"] - wa[g]["dmap_points"]}
             for g in sorted(set(wa) & set(wb))]
    diffs = [float(r["difference"]) for r in rows]
    in_se = [float(r["in_se"]) for r in rows if r["in_se"] is not None]
    ba, bb = ta["models"][model]["baseline_map"], tb["models"][model]["baseline_map"]
    summary = {
        "baseline_map_a": 100 * ba, "baseline_map_b": 100 * bb,
        "cells": len(rows), "cells_equal": sum(d == 0 for d in diffs),
        **_difference_stats(diffs),
        "loss_difference_max_in_se": max(in_se) if in_se else None,
        "worst_transform_changed": sum(w["transform_a"] != w["transform_b"] for w in worst),
        "worst_difference_max_abs": max((abs(w["difference"]) for w in worst), default=None),
    }
    return {"model": model, "summary": summary, "losses": rows, "worst_case": worst}


def rows_markdown(result: dict[str, Any], a_name: str, b_name: str) -> str:
    s = result["summary"]
    worst_changed = [w for w in result["worst_case"] if w["transform_a"] != w["transform_b"]]
    lines = [
        f"# One detector's rows measured twice: {result['model']}",
        "",
        "Written by `python -m benchmarks.tools.cross_machine rows A B --model "
        f"{result['model']}` from two `tables.json`.",
        "",
        f"- A: {a_name}",
        f"- B: {b_name}",
        "",
        f"Baseline mAP: A {s['baseline_map_a']:.4f}, B {s['baseline_map_b']:.4f} "
        f"(B − A {s['baseline_map_b'] - s['baseline_map_a']:+.5f} points).",
        "",
        f"ΔmAP over {s['cells']} cells ({s['cells_equal']} equal): B − A mean "
        f"{s['loss_difference_mean']:+.4f} points, SD {s['loss_difference_sd']:.4f}, largest "
        f"|B − A| {s['loss_difference_max_abs']:.4f} ({s['loss_difference_max_in_se']:.3f} of "
        "the cell's SE at most).",
        "",
        f"Worst case per ΔE: largest |B − A| {s['worst_difference_max_abs']:.4f} points; the "
        f"worst transform differs at {s['worst_transform_changed']} of "
        f"{len(result['worst_case'])} ΔE"
        + (": " + ", ".join(f"ΔE {w['delta_e']:g} {w['transform_a']} → {w['transform_b']}"
                            for w in worst_changed) if worst_changed else "") + ".",
        "",
        "| cell | mAP A | mAP B | ΔmAP A | ΔmAP B | B − A | SE B |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    lines += [f"| {r['cell']} | {r['map_a']:.4f} | {r['map_b']:.4f} | {r['loss_a']:+.4f} | "
              f"{r['loss_b']:+.4f} | {r['difference']:+.4f} | "
              + (f"{r['se_b']:.2f}" if r["se_b"] is not None else "–") + " |"
              for r in result["losses"]]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="verb", required=True)
    d = sub.add_parser("digest")
    d.add_argument("store")
    d.add_argument("out")
    d.add_argument("--model")
    d.add_argument("--cpu-here", action="store_true")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--out", default="reports/coco/cross_machine")
    c.add_argument("--stores", nargs=2, metavar=("STORE_A", "STORE_B"))
    r = sub.add_parser("rows")
    r.add_argument("a")
    r.add_argument("b")
    r.add_argument("--model", required=True)
    r.add_argument("--a-name", help="how the report names A (default: its path)")
    r.add_argument("--b-name", help="how the report names B (default: its path)")
    r.add_argument("--out")
    args = ap.parse_args(argv)
    if args.verb == "rows":
        doc_a, doc_b = (json.loads(Path(p).read_text(encoding="utf-8")) for p in (args.a, args.b))
        rows = compare_rows(doc_a, doc_b, args.model)
        write_report(args.out or f"reports/coco/cross_machine_rows_{args.model}", rows,
                     rows_markdown(rows, args.a_name or args.a, args.b_name or args.b))
        return
    if args.verb == "digest":
        from fidelity.core.fileio import write_text_atomic

        doc = digest_store(args.store, args.model)
        if args.cpu_here:
            from fidelity.coco.machine import cpu_description

            doc["machine"] = (doc["machine"] or {}) | cpu_description()
        write_text_atomic(Path(args.out), json.dumps(doc) + "\n")
        return
    a, b = (json.loads(Path(p).read_text(encoding="utf-8")) for p in (args.a, args.b))
    result = compare(a, b)
    if args.stores:
        result["differences"] = store_differences(args.stores[0], args.stores[1], a["model"])
    write_report(args.out, {"a": {k: a[k] for k in ("model", "machine", "versions")},
                            "b": {k: b[k] for k in ("model", "machine", "versions")},
                            **result}, markdown(a, b, result))


if __name__ == "__main__":
    main()
