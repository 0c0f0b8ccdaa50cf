"""``fidelity coco-c``: COCO-C's colour corruptions on the chart ΔE scale, measured on COCO."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.context import show_progress
from fidelity.cli.options import (
    CorruptionNames,
    ModelList,
    Severities,
    common_options,
    limit_option,
    progress_option,
)
from fidelity.cli.values import coco_inputs, model_inputs
from fidelity.coco.corruptions import CocoCResults, run_coco_c, with_predictions
from fidelity.coco.measure import stderr_log
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import check_outputs
from fidelity.report.cococ import DELTA_E_FIGURE, LOSS_FIGURE, write_cococ_report

if TYPE_CHECKING:
    from fidelity.coco.sweep import ModelSpec


@click.command()
@click.option("--models", type=ModelList(), default=None,
              help="ONNX detectors, PATH[@N] comma-separated (default: the shared "
                   "yolox_nano.onnx).")
@click.option("--images", default=None, type=click.Path(file_okay=False),
              help="COCO image folder (default: $FIDELITY_SHARED/coco/val2017).")
@click.option("--annotations", default=None, type=click.Path(dir_okay=False),
              help="COCO annotations (default: the shared subset's).")
@limit_option()
@click.option("--corruptions", type=CorruptionNames(), default="all", show_default=True,
              help="brightness, contrast, saturate (comma-separated) or all.")
@click.option("--severities", type=Severities(), default="1-5", show_default=True,
              help="e.g. 1-5 or 1,3,5.")
@click.option("--out", required=True, type=click.Path(file_okay=False),
              help="Report folder (cococ.html, cococ.md, cococ.json, figures).")
@click.option("--data", "data", default=None, type=click.Path(dir_okay=False),
              help="Also write the table predict --coco-c reads (the shipped one is "
                   "fidelity/data/coco-c.json).")
@click.option("--store", default=None, type=click.Path(file_okay=False),
              help="Detections store (default $FIDELITY_CACHE/measure); rerun to resume.")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="onnxruntime intra-op threads.")
@click.option("--provider", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True)
@click.option("--report-only", is_flag=True,
              help="Rebuild the report from OUT/cococ.json (no inference).")
@click.option("--notes", default=None, type=click.Path(dir_okay=False, exists=True),
              help="Markdown file with a written analysis, included in the report.")
@progress_option
@common_options
def cococ(models: tuple[ModelSpec, ...] | None, images: str | None, annotations: str | None,
          limit: int | None, corruptions: list[str], severities: list[int], out: str,
          data: str | None, store: str | None, threads: int, provider: str, report_only: bool,
          notes: str | None, progress: bool | None) -> None:
    """Measure COCO-C's colour corruptions: chart ΔE and ΔmAP per severity.

    Applies brightness, contrast and saturate of imagecorruptions (severities 1-5) to the
    calibration chart (its chart ΔE) and to every COCO image (the measured ΔmAP ± SE per
    detector, against the cached ΔE = 0 baseline). One log line per cell on stderr; rerun the
    same line to resume.

    \b
    fidelity coco-c --models yolox_nano.onnx,yolo11n-int8dyn.onnx@250 --out reports/cococ \\
        --data fidelity/data/coco-c.json
    """
    out_dir = Path(out)
    check_outputs({f"--out ({n})": out_dir / n
                   for n in ("cococ.json", "cococ.html", "cococ.md", DELTA_E_FIGURE,
                             LOSS_FIGURE)} | {"--data": data},
                  {"--notes": notes, "--images": images, "--annotations": annotations,
                   **model_inputs(models)},
                  stores={"--store": store})
    text = Path(notes).read_text(encoding="utf-8") if notes else None
    if report_only:
        src = out_dir / "cococ.json"
        try:
            results = with_predictions(
                CocoCResults.from_json(json.loads(src.read_text(encoding="utf-8"))))
        except FileNotFoundError:
            raise InputFileError(f"{src}: no results to rebuild the report from") from None
    else:
        inputs = coco_inputs(images, annotations, models, what="fidelity coco-c")
        results = run_coco_c(inputs, corruptions, severities, limit=limit, store=store,
                             threads=threads, provider=provider,
                             progress=show_progress(progress), log=stderr_log)
    for p in write_cococ_report(results, out_dir, text, data):
        click.echo(f"wrote {p}")
