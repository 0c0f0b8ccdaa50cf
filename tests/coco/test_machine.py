"""Which processor computed a store's detections: read from /proc/cpuinfo, kept per machine."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import fidelity.coco.driver as driver
from fidelity.coco.driver import StoreRun
from fidelity.coco.machine import KERNEL_INSTRUCTIONS, cpu_description
from fidelity.coco.store import ResultsStore

INTEL = """processor\t: 0
vendor_id\t: GenuineIntel
model name\t: Intel(R) Xeon(R) Processor
flags\t\t: fpu sse4_1 avx avx2 fma avx512f avx512bw avx512_vnni avx_vnni amx_int8 amx_tile
processor\t: 1
model name\t: Intel(R) Xeon(R) Processor
flags\t\t: fpu sse4_1 avx avx2 fma avx512f avx512bw avx512_vnni avx_vnni amx_int8 amx_tile
"""
AMD = "model name : AMD EPYC 7B13\nflags : fpu sse4_1 avx avx2 fma f16c\n"
ARM = "processor : 0\nBogoMIPS : 50.00\nFeatures : fp asimd evtstrm asimddp i8mm sve\n"


def test_cpu_description_reads_the_model_and_the_kernel_choosing_instructions() -> None:
    intel = cpu_description(INTEL)
    assert intel["cpu"] == "Intel(R) Xeon(R) Processor"
    assert intel["instructions"] == ["sse4_1", "avx", "avx2", "fma", "avx512f", "avx512bw",
                                     "avx512_vnni", "avx_vnni", "amx_int8"]
    assert "amx_tile" not in intel["instructions"]  # not one that picks a kernel
    assert cpu_description(AMD) == {"cpu": "AMD EPYC 7B13",
                                    "instructions": ["sse4_1", "avx", "avx2", "fma", "f16c"]}
    arm = cpu_description(ARM)
    assert arm["instructions"] == ["asimd", "asimddp", "i8mm", "sve"]
    assert arm["cpu"]  # no model name line: the platform's word, never empty


@pytest.mark.parametrize("text", ["", "garbage without colons\n\x00\n", "flags :\n"])
def test_cpu_description_of_unreadable_or_empty_cpuinfo(text: str) -> None:
    d = cpu_description(text)
    assert d["cpu"]
    assert d["instructions"] in (None, [])
    if "flags" in text:
        assert d["instructions"] == []


def test_cpu_description_here_lists_known_instructions_only() -> None:
    d = cpu_description()
    assert d["instructions"] is None or set(d["instructions"]) <= set(KERNEL_INSTRUCTIONS)


def test_a_store_keeps_every_machine_that_ran_in_it(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    store = ResultsStore(tmp_path)
    run: StoreRun[Any] = StoreRun(store, lambda: ResultsStore(tmp_path, create=False),
                                  None, None)  # type: ignore[arg-type]
    monkeypatch.setattr(driver, "cpu_description", lambda: cpu_description(AMD))
    run.record_machine({"threads": 2})
    run.record_machine({"threads": 1})  # same machine, other settings: still one machine
    meta = store.meta()
    assert meta["machine"]["cpu"] == "AMD EPYC 7B13" and meta["machine"]["threads"] == 1
    assert len(meta["machines"]) == 1
    monkeypatch.setattr(driver, "cpu_description", lambda: cpu_description(INTEL))
    run.record_machine({"threads": 2})  # resumed on another processor
    machines = store.meta()["machines"]
    assert [m["cpu"] for m in machines] == ["AMD EPYC 7B13", "Intel(R) Xeon(R) Processor"]
    assert "avx512_vnni" in machines[1]["instructions"]
    assert "threads" not in machines[0]  # the machine, not the run's settings
    store.close()


def _doc(maps: dict[str, float], digests: dict[str, dict[str, str]]) -> dict[str, Any]:
    cells = [[k.split(":")[0], float(k.split(":")[1]), 3, m] for k, m in maps.items()]
    return {"model": "m", "machine": None, "versions": None, "cells": cells,
            "digests": digests}


def test_cross_machine_comparison_counts_images_and_differences_of_losses() -> None:
    from benchmarks.tools.cross_machine import compare, markdown, version_differences

    a = _doc({"baseline:0": 0.40, "hue:1": 0.39, "hue:3": 0.38},
             {"baseline:0": {"1": "a", "2": "b", "3": "c"}, "hue:1": {"1": "d", "2": "e"}})
    b = _doc({"baseline:0": 0.41, "hue:1": 0.395, "hue:3": 0.38},
             {"baseline:0": {"1": "a", "2": "x", "3": "c"}, "hue:1": {"1": "d", "9": "z"}})
    r = compare(a, b)
    s = r["summary"]
    assert (s["images_compared"], s["identical"]) == (4, 3)  # image 9 is only in b
    losses = {row["cell"]: row for row in r["losses"]}
    assert losses["hue:1"]["loss_a"] == pytest.approx(1.0)
    assert losses["hue:1"]["loss_b"] == pytest.approx(1.5)
    assert losses["hue:3"]["difference"] == pytest.approx(1.0)  # 3.0 on b against 2.0 on a
    assert s["loss_difference_mean"] == pytest.approx(0.75)
    assert s["loss_difference_max_abs"] == pytest.approx(1.0)
    assert "3 of 4" in markdown(a, b, r)
    assert "same library versions" in markdown(a, b, r)
    fewer = _doc({"baseline:0": 0.41, "hue:1": 0.395}, b["digests"])
    fewer["cells"] = [[t, g, 2, m] for t, g, _, m in fewer["cells"]]  # a run of 2 images
    other = compare(a, fewer)
    assert other["losses"] == [] and other["summary"]["baseline_map_a"] is None
    assert other["summary"]["identical"] == 3  # the images both ran still compare
    a["versions"] = {"python": "3.11.7", "onnxruntime": "1.32.0", "fidelity": "0.1.0"}
    b["versions"] = {"python": "3.11.7", "onnxruntime": "1.30.0", "numpy": "2.5.2",
                     "fidelity": "0.0.0+source"}
    assert version_differences(a, b) == {"numpy": [None, "2.5.2"],
                                         "onnxruntime": ["1.32.0", "1.30.0"]}
    assert "onnxruntime 1.32.0 / 1.30.0" in markdown(a, b, r)
    empty = compare(_doc({}, {}), _doc({}, {}))["summary"]
    assert empty["identical_fraction"] is None and empty["loss_difference_mean"] is None


def _tables_doc(baseline: float, cells: dict[str, tuple[float, float, float | None]],
                worst: dict[float, tuple[str, float]]) -> dict:
    """A minimal tables.json of detector "m": cells "transform:ΔE" -> (mAP, ΔmAP, SE)."""
    rows = [{"transform": k.split(":")[0], "delta_e": float(k.split(":")[1]), "status": "done",
             "map": m, "dmap_points": d, "dmap_points_se": se}
            for k, (m, d, se) in cells.items()]
    rows.append({"transform": "hue", "delta_e": 24.0, "status": "unreachable", "map": None,
                 "dmap_points": None})
    wc = [{"delta_e": 0.0, "worst_transform": None, "dmap_points": 0.0}]
    wc += [{"delta_e": g, "worst_transform": t, "dmap_points": d} for g, (t, d) in worst.items()]
    return {"tables": {"models": {"m": {"baseline_map": baseline}}, "cells": {"m": rows},
                       "worst_case": {"m": wc}}}


def test_cross_machine_rows_compare_a_detectors_whole_grid_of_two_tables() -> None:
    from benchmarks.tools.cross_machine import compare_rows, rows_markdown

    a = _tables_doc(0.30, {"hue:1": (0.299, 0.1, 0.5), "gamma-inc:1": (0.298, 0.2, 0.4),
                           "hue:3": (0.29, 1.0, 0.8)},
                    {1.0: ("gamma-inc", 0.2), 3.0: ("hue", 1.0)})
    b = _tables_doc(0.30, {"hue:1": (0.2988, 0.12, 0.5), "gamma-inc:1": (0.298, 0.2, 0.4),
                           "hue:3": (0.29, 1.0, None), "hue:6": (0.28, 2.0, 1.0)},
                    {1.0: ("gamma-inc", 0.2), 3.0: ("hue", 1.0), 6.0: ("hue", 2.0)})
    b["tables"]["cells"]["m"][0]["dmap_points"] = 0.25  # hue:1 moves by 0.15 points
    b["tables"]["worst_case"]["m"][1] = {"delta_e": 1.0, "worst_transform": "hue",
                                         "dmap_points": 0.25}
    r = compare_rows(a, b, "m")
    s = r["summary"]
    assert s["cells"] == 3 and s["cells_equal"] == 2  # hue:6 only in b, hue:24 unreachable
    by = {row["cell"]: row for row in r["losses"]}
    assert by["hue:1"]["difference"] == pytest.approx(0.15)
    assert by["hue:1"]["in_se"] == pytest.approx(0.3)  # 0.15 of b's SE 0.5
    assert by["hue:3"]["in_se"] is None  # b states no SE there
    assert s["loss_difference_mean"] == pytest.approx(0.05)
    assert s["loss_difference_max_abs"] == pytest.approx(0.15)
    assert s["loss_difference_max_in_se"] == pytest.approx(0.3)
    assert s["worst_transform_changed"] == 1 and s["worst_difference_max_abs"] == pytest.approx(
        0.05)
    assert [w["delta_e"] for w in r["worst_case"]] == [1.0, 3.0]  # ΔE 0 and b's ΔE 6 left out
    text = rows_markdown(r, "first", "second")
    assert "ΔE 1 gamma-inc → hue" in text and "| hue:3 |" in text and "| – |" in text


def test_detection_differences_pair_each_detection_with_the_nearest_of_its_class() -> None:
    import numpy as np

    from benchmarks.tools.cross_machine import detection_differences

    d = np.array([[10, 10, 50, 50, 0.90, 0], [12, 11, 52, 49, 0.90, 0],
                  [0, 0, 5, 5, 0.30, 2]], np.float32)
    swapped = d[[1, 0, 2]].copy()  # two near-equal scores in the other order
    moved = d.copy()
    moved[2, :4] += 0.5
    moved[0, 4] -= 0.25
    other = d.copy()
    other[2, 5] = 3
    r = detection_differences({1: d, 2: d, 3: d, 4: d, 5: d[:0]},
                              {1: swapped, 2: moved, 3: other, 4: d[:2], 5: d[:0], 6: d})
    assert (r["matched"], r["unmatched"]) == (3, 2)  # images 1, 2, 5; 3 and 4; 6 only in b
    assert r["max_box_px"] == pytest.approx(0.5)
    assert r["max_score"] == pytest.approx(0.25)
    same = detection_differences({1: d}, {1: swapped})
    assert same["max_box_px"] == 0 and same["max_score"] == 0
