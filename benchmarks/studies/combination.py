"""Do the losses of blur and noise add? The combination rule of a verdict measured on COCO.

A verdict sums the predicted losses of colour, sharpness and noise
(:data:`fidelity.prediction.properties.COMBINATION`). This study measures, per detector, the
loss of a blur and a noise applied together (blur first, as a camera does: optics, then the
sensor) against the losses of each alone, on the same images, baseline and JPEG round trip as
every sweep cell (:func:`fidelity.coco.measure.measure_mapping`), with their standard errors:

- ``measured_sum``: blur alone + noise alone; ``measured_joint``: both together;
  ``interaction`` = joint - sum (with its standard error, the alone and joint ones combined in
  quadrature: an upper bound, the three share the baseline);
- ``predicted_sum``: what a verdict predicts for the composite: the calibration chart degraded
  by the composite and measured as an audit measures it (MTF50, SNR at 18 % grey), each
  property's worst case from the shipped tables (size n), summed; ``covered`` says whether it
  is at least the joint loss measured (the rule's promise: a worst-case upper bound).

Writes ``reports/validation/combination.json`` and ``.md``.

Usage: python -m benchmarks.studies.combination IMAGES ANNOTATIONS MODEL.onnx[@N] ...
       [--store DIR] [--out reports/validation/combination]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.coco.degradations import Degradation
from fidelity.coco.measure import CocoInputs, measure_mapping, resolve_coco_inputs
from fidelity.coco.tables.degradation import calibration_chart, chart_value
from fidelity.core.fileio import write_json_atomic, write_text_atomic
from fidelity.prediction.properties import (
    COMBINATION,
    combine,
    load_property_table,
    predict_property,
)

#: The composites measured: (blur family, level), (noise family, level).
CASES: tuple[tuple[tuple[str, float], tuple[str, float]], ...] = (
    (("gaussian-blur", 1.0), ("gaussian-noise", 0.03)),
    (("gaussian-blur", 1.5), ("gaussian-noise", 0.06)),
    (("gaussian-blur", 2.0), ("sensor-noise", 600.0)),
)


def composite(*steps: Degradation) -> Callable[[np.ndarray], np.ndarray]:
    """The steps applied in order (uint8 sRGB -> uint8 sRGB)."""
    def apply(rgb: np.ndarray) -> np.ndarray:
        for step in steps:
            rgb = step(rgb)
        return rgb
    return apply


def _key(*steps: Degradation) -> str:
    return "combination:" + "+".join(f"{s.name}@{s.level:g}" for s in steps)


def predicted(*steps: Degradation) -> dict[str, Any]:
    """What a verdict predicts for the composite on the calibration chart (size n)."""
    image, corners = calibration_chart()
    degraded = composite(*steps)(image)
    out: dict[str, Any] = {}
    total = 0.0
    for prop in ("sharpness", "noise"):
        got = chart_value(degraded, corners, prop)
        if got is None:
            out[prop] = None
            continue
        p = predict_property(load_property_table(prop), got[0], size="n")
        out[prop] = {"x": got[0], "loss": p.loss, "family": p.family, "detector": p.detector}
        total += p.loss
    out["sum"] = total
    out["combined"] = predicted_combined(out)
    return out


def predicted_combined(pred: dict[str, Any]) -> float:
    """The verdict's combined loss (:func:`fidelity.prediction.properties.combine`, the
    shipped rule) of a case's predicted parts."""
    parts = {p: (pred[p]["loss"], None) for p in ("sharpness", "noise") if pred.get(p)}
    return combine(parts).loss if parts else 0.0


def _measure(fn: Callable[[np.ndarray], np.ndarray], key: str, inputs: CocoInputs,
             store: str | None, say: Callable[[str], None]) -> dict[str, dict[str, float]]:
    losses = measure_mapping(fn, key, inputs, store=store, threads=2, provider="cpu",
                             log=say)
    return {m.model: {"loss": m.dmap_points, "se": m.dmap_points_se or 0.0, "images": m.images}
            for m in losses}


def parse_case(text: str) -> tuple[tuple[str, float], tuple[str, float]]:
    """``BLUR@LEVEL+NOISE@LEVEL`` (``gaussian-blur@2.5+gaussian-noise@0.02``) as a case."""
    try:
        (a, la), (b, lb) = (part.split("@") for part in text.split("+"))
        return (a, float(la)), (b, float(lb))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give BLUR@LEVEL+NOISE@LEVEL, e.g. gaussian-blur@2+sensor-noise@600"
        ) from None


def run(inputs: CocoInputs, store: str | None, say: Callable[[str], None],
        done: Callable[[dict[str, Any]], None] = lambda doc: None,
        cases: Sequence[tuple[tuple[str, float], tuple[str, float]]] = CASES
        ) -> dict[str, Any]:
    """Every case: the losses alone and together per detector, and the prediction;
    ``done`` is called with the document so far after each case."""
    rows: list[dict[str, Any]] = []
    for (blur, b_level), (noise, n_level) in cases:
        a, b = Degradation(blur, b_level), Degradation(noise, n_level)
        t0 = time.perf_counter()
        alone_a = _measure(composite(a), _key(a), inputs, store, say)
        alone_b = _measure(composite(b), _key(b), inputs, store, say)
        joint = _measure(composite(a, b), _key(a, b), inputs, store, say)
        pred = predicted(a, b)
        per_model = {}
        for model, j in joint.items():
            s = alone_a[model]["loss"] + alone_b[model]["loss"]
            se = math.sqrt(alone_a[model]["se"] ** 2 + alone_b[model]["se"] ** 2
                           + j["se"] ** 2)
            per_model[model] = {"images": j["images"],
                                "blur": alone_a[model], "noise": alone_b[model], "joint": j,
                                "measured_sum": s, "interaction": j["loss"] - s,
                                "interaction_se": se,
                                "covered": pred["combined"] >= j["loss"],
                                "covered_by_sum": pred["sum"] >= j["loss"]}
        rows.append({"blur": {"family": blur, "level": b_level},
                     "noise": {"family": noise, "level": n_level},
                     "predicted": pred, "models": per_model,
                     "seconds": time.perf_counter() - t0})
        done(_document(rows))
    return _document(rows)


def _document(rows: list[dict[str, Any]]) -> dict[str, Any]:
    return {"cases": rows, "order": "blur, then noise (optics before the sensor)",
            "loss": "ΔmAP points (COCO mAP@[.50:.95], 100 x (baseline - degraded))",
            "combination_rule": COMBINATION}


def markdown(doc: dict[str, Any], title: str = "Do blur and noise losses add?") -> str:
    """The study as a page; every sentence from the numbers. The verdict's combined loss is
    computed from each case's predicted parts by the shipped rule
    (:func:`predicted_combined`), so a page of an earlier run shows the rule as it is now."""
    lines = [f"# {title}", "",
             "Per detector: the loss of each degradation alone and of both together (blur "
             "first), on the same images; the interaction is joint minus the sum of the two "
             "alone (± its standard error, the three combined in quadrature). The prediction "
             "is what a verdict predicts for the composite measured on the calibration chart: "
             "the sum of the two properties' worst-case losses, and the combined loss by the "
             f"shipped rule ({COMBINATION}) (`benchmarks/studies/combination.py`).", "",
             "| blur | noise | detector | images | blur alone | noise alone | sum | together | "
             "interaction | interaction / sqrt(product) | predicted sum | predicted combined "
             "| covered by the sum | covered by the rule |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    n_cov = n_sum = n_all = n_sub = 0
    ratios = []
    for c in doc["cases"]:
        combined = predicted_combined(c["predicted"])
        for model, m in c["models"].items():
            n_all += 1
            joint = m["joint"]["loss"]
            n_cov += combined >= joint
            n_sum += c["predicted"]["sum"] >= joint
            n_sub += m["interaction"] <= 2 * m["interaction_se"]
            product = max(m["blur"]["loss"], 0.0) * max(m["noise"]["loss"], 0.0)
            ratio = m["interaction"] / math.sqrt(product) if product > 0 else math.nan
            ratios.append(ratio)
            lines.append(
                f"| {c['blur']['family']} {c['blur']['level']:g} | {c['noise']['family']} "
                f"{c['noise']['level']:g} | {model} | {m.get('images', '–')} | "
                f"{m['blur']['loss']:.2f} ± {m['blur']['se']:.2f} | {m['noise']['loss']:.2f} ± "
                f"{m['noise']['se']:.2f} | {m['measured_sum']:.2f} | {joint:.2f} ± "
                f"{m['joint']['se']:.2f} | {m['interaction']:+.2f} ± {m['interaction_se']:.2f} | "
                f"{f'{ratio:+.2f}' if math.isfinite(ratio) else '–'} | "
                f"{c['predicted']['sum']:.2f} | {combined:.2f} | "
                f"{'yes' if c['predicted']['sum'] >= joint else 'no'} | "
                f"{'yes' if combined >= joint else 'no'} |")
    top = max((r for r in ratios if math.isfinite(r)), default=math.nan)
    lines += ["", f"The predicted sum is at least the joint loss measured in {n_sum} of "
              f"{n_all} cases, the combined loss by the rule in {n_cov} of {n_all}. The joint "
              f"loss is at most the measured sum plus twice its standard error (no "
              f"super-additive interaction shown) in {n_sub} of {n_all}; the largest "
              f"interaction is {top:.2f} sqrt(blur alone x noise alone).", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("images")
    ap.add_argument("annotations")
    ap.add_argument("models", nargs="+")
    ap.add_argument("--store", default=None, help="The measurement store (resumable).")
    ap.add_argument("--out", default="reports/validation/combination")
    ap.add_argument("--case", dest="cases", action="append", type=parse_case, default=None,
                    metavar="BLUR@L+NOISE@L",
                    help="A composite to measure (repeatable; default: the study's CASES).")
    ap.add_argument("--title", default="Do blur and noise losses add?",
                    help="The page's title.")
    args = ap.parse_args(argv)
    inputs = resolve_coco_inputs(args.images, args.annotations, ",".join(args.models))
    out = Path(args.out)

    def write(doc: dict[str, Any]) -> None:
        write_json_atomic(out.with_suffix(".json"), doc)
        write_text_atomic(out.with_suffix(".md"), markdown(doc, args.title))

    doc = run(inputs, args.store, print, write, args.cases or CASES)
    print(json.dumps({c["blur"]["family"] + str(c["blur"]["level"]): c["predicted"]["combined"]
                      for c in doc["cases"]}))


if __name__ == "__main__":
    main()
