"""``fidelity evaluate``: run one ONNX detector on a COCO image folder and score it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.cli.context import show_progress, write_json_output
from fidelity.cli.options import (
    ModelList,
    common_options,
    executor_options,
    json_option,
    limit_option,
    progress_option,
    scorer_option,
)
from fidelity.cli.values import cap_models, executor_from
from fidelity.coco.evaluate import METRICS, evaluate_model
from fidelity.core.fileio import check_outputs, remove_stale_temporaries

if TYPE_CHECKING:
    from fidelity.coco.sweep import ModelSpec


@click.command()
@click.option("--models", "model", required=True, type=ModelList(),
              help="ONNX detector, PATH[@N] (Ultralytics 1x84xN, YOLOv10 1x300x6 or YOLOX "
                   "1xNx85); one.")
@click.option("--images", required=True, type=click.Path(file_okay=False),
              help="Folder with the images named in the annotations.")
@click.option("--annotations", required=True, type=click.Path(dir_okay=False),
              help="COCO instances JSON (box annotations).")
@limit_option()
@click.option("--threads", type=click.IntRange(min=1), default=None,
              help="onnxruntime intra-op threads (default: all cores).")
@click.option("--provider", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True, help="Execution provider (auto: CUDA if present).")
@json_option("Write map, map50, ap (class -> AP), images, seconds as JSON (fractions)")
@click.option("--classes", default="person,bicycle,car,motorcycle,bus,truck,traffic light,stop sign",
              show_default=True, help="Classes whose AP is printed (all are in --json).")
@click.option("--metric", "metrics", multiple=True, type=click.Choice(list(METRICS)),
              default=("coco",), show_default=True,
              help="Also report Ultralytics' own mAP50-95 (yolo val's number: 101-point "
                   "envelope integrated by the trapezoid rule, crowd boxes as false "
                   "positives); 'ultralytics' follows Ultralytics 8.4, 'ultralytics-8.3' the "
                   "older rules. COCO AP is always reported. Repeatable.")
@scorer_option
@progress_option
@executor_options
@common_options
def evaluate(model: tuple[ModelSpec, ...], images: str, annotations: str, limit: int | None,
             threads: int | None, provider: str, json_path: str | None, classes: str, metrics: tuple[str, ...],
             scorer: str, progress: bool | None, executor: str, address: str | None,
             workers: int | None) -> None:
    """Run detectors on a COCO image folder and print COCO box AP.

    Detections are kept per image in a store in the cache ($FIDELITY_CACHE/evaluate), so an
    interrupted evaluation started again runs only the images it had not finished.
    """
    if len(model) != 1:
        raise click.UsageError("evaluate takes one model in --models (sweep takes several)")
    (spec,) = cap_models(model, limit)
    check_outputs({"--json": json_path},
                  {"--models": spec.path, "--annotations": annotations, "--images": images})
    options = executor_from(executor, address, workers, threads, provider)
    if json_path and json_path != "-":
        remove_stale_temporaries(Path(json_path).parent)
    ev = evaluate_model(spec.path, images, annotations, limit=spec.limit, options=options,
                        scorer=scorer, metrics=metrics, progress=show_progress(progress))
    info = ev.detector
    conv = info["conventions"]
    score = ev.coco
    click.echo(f"model      {info['model']}  layout {info['layout']}  input {info['input_size']}  "
               f"batch {info['batch']}  providers {','.join(info['providers'])}")
    click.echo(f"settings   conf {conv['conf']}  iou {conv['iou']}  max_det {conv['max_det']}  "
               f"({conv['source']})")
    click.echo(f"preprocess {info['preprocessing']}")
    rate = (f"{ev.computed / ev.detect_seconds:.1f} img/s detection"
            if ev.computed and ev.detect_seconds else "no inference")
    earlier = ev.images - ev.computed
    click.echo(f"images     {ev.images}  detections {score.detections}  {rate}  "
               f"{ev.seconds:.1f} s total  (scored by {ev.scorer})"
               + (f"  {earlier} from an earlier run's store" if earlier else ""))
    click.echo(f"mAP        {score.map:.4f}   (COCO AP@[.50:.95], fraction)")
    click.echo(f"AP50       {score.map50:.4f}")
    for name, u in ev.ultralytics.items():
        click.echo(f"{name} mAP50-95 {u.map:.4f}  mAP50 {u.map50:.4f}   (Ultralytics {u.version} "
                   f"rules, {u.targets} targets)")
    for name in [c.strip() for c in classes.split(",") if c.strip()]:
        v = score.ap.get(name)
        click.echo(f"AP {name:<14} {'n/a (no ground truth)' if v is None else f'{v:.4f}'}")
    if json_path:
        payload = ev.to_json() | {"annotations": str(annotations), "images_dir": str(images)}
        click.echo(f"wrote {write_json_output(json_path, payload)}")
