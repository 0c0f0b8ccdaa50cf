"""``fidelity evaluate``: run one ONNX detector on a COCO image folder and score it."""

from __future__ import annotations

import time
from pathlib import Path

import click

from fidelity.cli.executor import executor_from, executor_options
from fidelity.cli.options import (
    common_options,
    json_option,
    progress_option,
    show_progress,
    write_json_output,
)
from fidelity.coco.scoring import COCO_SCORERS

#: ``--scorer``, shared by the commands that score COCO AP (evaluate, sweep).
scorer_option = click.option(
    "--scorer", type=click.Choice(["auto", *COCO_SCORERS]), default="auto", show_default=True,
    help="COCO AP implementation: pycocotools (reference) or faster-coco-eval (same numbers "
         "to 1e-4, tested; ~6x faster); auto: faster-coco-eval if installed.")


@click.command()
@click.option("--models", "model", required=True, type=click.Path(dir_okay=False),
              help="ONNX detector (Ultralytics 1x84xN, YOLOv10 1x300x6 or YOLOX 1xNx85).")
@click.option("--images", required=True, type=click.Path(file_okay=False),
              help="Folder with the images named in the annotations.")
@click.option("--annotations", required=True, type=click.Path(dir_okay=False),
              help="COCO instances JSON (box annotations).")
@click.option("--limit", type=click.IntRange(min=1), default=None,
              help="Evaluate only the first N images by image id.")
@click.option("--threads", type=click.IntRange(min=1), default=None,
              help="onnxruntime intra-op threads (default: all cores).")
@click.option("--provider", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True, help="Execution provider (auto: CUDA if present).")
@json_option("Write map, map50, ap (class -> AP), images, seconds as JSON (fractions)")
@click.option("--classes", default="person,bicycle,car,motorcycle,bus,truck,traffic light,stop sign",
              show_default=True, help="Classes whose AP is printed (all are in --json).")
@scorer_option
@progress_option
@executor_options
@common_options
def evaluate(model: str, images: str, annotations: str, limit: int | None, threads: int | None,
             provider: str, json_path: str | None, classes: str, scorer: str,
             progress: bool | None, executor: str, address: str | None,
             workers: int | None) -> None:
    """Run detectors on a COCO image folder and print COCO box AP.

    Detections are kept per image in a store in the cache ($FIDELITY_CACHE/evaluate), so an
    interrupted evaluation started again runs only the images it had not finished.
    """
    from fidelity.coco.executor import ModelFile, detect_images
    from fidelity.coco.scoring import evaluate_detections, load_annotations, resolve_scorer
    from fidelity.coco.store import ImageSet
    from fidelity.errors import InputFileError
    from fidelity.fileio import check_outputs, remove_stale_temporaries

    check_outputs({"--json": json_path},
                  {"--model": model, "--annotations": annotations, "--images": images})
    options = executor_from(executor, address, workers, threads, provider)
    detector = ModelFile.from_path(model)  # a missing model is named first
    coco = load_annotations(annotations)
    all_ids = sorted(coco.getImgIds())
    ids = all_ids[:limit] if limit else all_ids
    folder = Path(images)
    if not folder.is_dir():
        raise InputFileError(f"{folder}: image folder does not exist")
    missing = [i for i in ids if not (folder / coco.imgs[i]["file_name"]).is_file()]
    if missing:  # before any inference
        raise InputFileError(f"{folder}: {len(missing)} of the {len(ids)} annotated images "
                             f"to evaluate are missing, e.g. {coco.imgs[missing[0]]['file_name']}")
    if json_path and json_path != "-":
        remove_stale_temporaries(Path(json_path).parent)
    t0 = time.perf_counter()
    found = detect_images(detector, ImageSet(folder, coco, ids), ids, options,
                          progress=show_progress(progress))
    dets = found.detections
    method = resolve_scorer(scorer)
    score = evaluate_detections(coco, dets, ids, method=method)
    seconds = time.perf_counter() - t0
    info = found.detector
    conv = info["conventions"]
    click.echo(f"model      {info['model']}  layout {info['layout']}  input "
               f"{info['input_size']}  providers {','.join(info['providers'])}")
    click.echo(f"settings   conf {conv['conf']}  iou {conv['iou']}  max_det {conv['max_det']}  "
               f"({conv['source']})")
    rate = (f"{found.new / found.seconds:.1f} img/s inference" if found.new and found.seconds
            else "no inference")
    earlier = len(ids) - found.new
    click.echo(f"images     {len(ids)}  detections {score.detections}  {rate}  "
               f"{seconds:.1f} s total  (scored by {method})"
               + (f"  {earlier} from an earlier run's store" if earlier else ""))
    click.echo(f"mAP        {score.map:.4f}   (AP@[.50:.95], fraction)")
    click.echo(f"AP50       {score.map50:.4f}")
    for name in [c.strip() for c in classes.split(",") if c.strip()]:
        v = score.ap.get(name)
        click.echo(f"AP {name:<14} {'n/a (no ground truth)' if v is None else f'{v:.4f}'}")
    if json_path:
        payload = score.to_dict() | {"seconds": seconds, "detector": info,
                                     "annotations": str(annotations), "images_dir": str(images),
                                     "scorer": method, "executor": found.executor,
                                     "computed": found.new}
        click.echo(f"wrote {write_json_output(json_path, payload)}")

