"""``fidelity coco-c``: COCO-C's colour corruptions on the chart ΔE scale and its noise and blur
corruptions on the SNR and MTF50 scales, measured on COCO."""

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
from fidelity.coco.corruptions import (
    CocoCResults,
    merge_results,
    run_coco_c,
    with_predictions,
)
from fidelity.coco.measure import stderr_log
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import check_outputs
from fidelity.report.cococ import FIGURES, write_cococ_report

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
              help="brightness, contrast, saturate (chart ΔE), gaussian_noise, shot_noise "
                   "(SNR), defocus_blur, gaussian_blur (MTF50), comma-separated, or all.")
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
@click.option("--update", is_flag=True,
              help="Keep the cells of OUT/cococ.json this run does not measure (e.g. add the "
                   "noise and blur corruptions to a report of the colour ones).")
@click.option("--notes", default=None, type=click.Path(dir_okay=False, exists=True),
              help="Markdown file with a written analysis, included in the report.")
@progress_option
@common_options
def cococ(models: tuple[ModelSpec, ...] | None, images: str | None, annotations: str | None,
          limit: int | None, corruptions: list[str], severities: list[int], out: str,
          data: str | None, store: str | None, threads: int, provider: str, report_only: bool,
          update: bool, notes: str | None, progress: bool | None) -> None:
    """Measure COCO-C's corruptions: chart value and ΔmAP per severity.

    Applies imagecorruptions' brightness, contrast and saturate (severities 1-5) to the
    calibration chart (its chart ΔE), and its gaussian_noise, shot_noise (the chart's SNR at
    18 % grey), defocus_blur and gaussian_blur (the chart's MTF50), each noise seeded per
    image; then to every COCO image (the measured ΔmAP ± SE per detector, against the cached
    ΔE = 0 baseline). One log line per cell on stderr; rerun the same line to resume.

    \b
    fidelity coco-c --models yolox_nano.onnx,yolo11n-int8dyn.onnx@250 --out reports/cococ \\
        --data fidelity/data/coco-c.json
    fidelity coco-c --corruptions gaussian_noise,shot_noise,defocus_blur,gaussian_blur \\
        --update --out reports/cococ --data fidelity/data/coco-c.json
    """
    out_dir = Path(out)
    check_outputs({f"--out ({n})": out_dir / n
                   for n in ("cococ.json", "cococ.html", "cococ.md", *FIGURES)}
                  | {"--data": data},
                  {"--notes": notes, "--images": images, "--annotations": annotations,
                   **model_inputs(models)},
                  stores={"--store": store})
    text = Path(notes).read_text(encoding="utf-8") if notes else None
    if report_only and update:
        raise click.UsageError("--update adds measured cells: not with --report-only")
    src = out_dir / "cococ.json"
    if report_only:
        results = with_predictions(_read_results(src, "no results to rebuild the report from"))
    else:
        base = (with_predictions(_read_results(src, "no results to update (run without "
                                                    "--update first)")) if update else None)
        inputs = coco_inputs(images, annotations, models, what="fidelity coco-c")
        results = run_coco_c(inputs, corruptions, severities, limit=limit, store=store,
                             threads=threads, provider=provider,
                             progress=show_progress(progress), log=stderr_log)
        if base is not None:
            results = merge_results(base, results)
    for p in write_cococ_report(results, out_dir, text, data):
        click.echo(f"wrote {p}")


def _read_results(src: Path, missing: str) -> CocoCResults:
    """The results of an earlier run (``OUT/cococ.json``); ``missing``: the error's words
    when there is none."""
    try:
        return CocoCResults.from_json(json.loads(src.read_text(encoding="utf-8")))
    except FileNotFoundError:
        raise InputFileError(f"{src}: {missing}") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise InputFileError(f"{src}: not a COCO-C results file ({exc})") from None
