"""``fidelity validate``: predicted against measured ΔmAP for a suite of camera models."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from fidelity.camera.model import camera_files
from fidelity.cli.context import show_progress
from fidelity.cli.options import (
    ModelList,
    common_options,
    executor_options,
    limit_option,
    progress_option,
    scores_options,
    suite_cat_option,
)
from fidelity.cli.values import cap_models, executor_from, model_inputs, transfer_scores
from fidelity.coco.emulation import EMULATION_METHODS, TRAINING_SETS
from fidelity.coco.scoring import load_annotations
from fidelity.coco.sweep import run_summary
from fidelity.coco.validate.colour import collect_results, run_validation, validated_cameras
from fidelity.coco.validate.properties import collect_property_results, validated_properties
from fidelity.coco.validate.store import ValidationStore, default_store
from fidelity.coco.validate.suite import load_suite
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.core.fileio import check_outputs, write_json_atomic
from fidelity.core.resources import resource_dir
from fidelity.report.format import number
from fidelity.report.propertyvalidation import write_property_report
from fidelity.report.validation import write_validation_report

if TYPE_CHECKING:
    from fidelity.coco.sweep import ModelSpec

#: The validated cameras (:func:`fidelity.coco.validate.colour.validated_cameras`), beside the report.
DOMAIN_FILE = "domain.json"
#: What ``validate --properties`` writes beside its report: the cameras of the sharpness and
#: noise validation (:func:`fidelity.coco.validate.properties.validated_properties`).
PROPERTIES_DOMAIN_FILE = "properties-domain.json"
#: The files of the property validation (``--properties``).
PROPERTY_FILES = ("properties.md", "properties.html", "properties.json")


@click.command()
@click.option("--cameras", default=None, type=click.Path(file_okay=False),
              help="Folder of camera files (+ optional suite.toml with scene illuminants and "
                   "chromatic adaptation transforms); default: the 30-camera suite that ships "
                   "with fidelity.")
@suite_cat_option("It adapts the reference each camera's chart ΔE is measured against (the "
                  "emulation's training reference stays Bradford).")
@click.option("--models", type=ModelList(), default=None,
              help="Comma-separated ONNX files, each optionally PATH@N (at most the first N "
                   "images by id).")
@click.option("--images", default=None, type=click.Path(file_okay=False),
              help="COCO image folder.")
@click.option("--annotations", default=None, type=click.Path(dir_okay=False),
              help="COCO annotation JSON.")
@click.option("--out", default=None, type=click.Path(file_okay=False),
              help="Report folder (Markdown, HTML, JSON, plots); needed except with "
                   "--export-scores and --import-scores.")
@limit_option()
@click.option("--store", default=None, type=click.Path(file_okay=False),
              help="Results store folder (default $FIDELITY_CACHE/validation or "
                   "~/.cache/fidelity/validation); rerun to resume.")
@click.option("--method", default="root-polynomial", show_default=True,
              help="Emulation method: root-polynomial or lut3d.")
@click.option("--training", default="colour-science", show_default=True,
              help="Training reflectances of the emulation: chart or colour-science.")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="onnxruntime intra-op threads.")
@click.option("--provider", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True)
@click.option("--table", "bound_table", default=None,
              help="Worst-case prediction table whose bound is tested (default: the default "
                   "table of fidelity predict).")
@click.option("--report-only", is_flag=True,
              help="Only write the report from what the store holds (no inference; with "
                   "--annotations, cells stored by an earlier version get the bootstrap "
                   "draws and rest-of-run fold scores of the standard error).")
@click.option("--notes", default=None, type=click.Path(dir_okay=False, exists=True),
              help="Markdown file with a written analysis, included in the report.")
@click.option("--properties", is_flag=True,
              help="Judge the cameras as a verdict does, colour, sharpness and noise combined "
                   "(their optics and noise emulated on COCO), and write properties.md, .html "
                   "and .json in place of the colour report.")
@scores_options("--store")
@progress_option
@executor_options
@common_options
def validate(cameras: str | None, models: tuple[ModelSpec, ...] | None, images: str | None, annotations: str | None,
             out: str | None, cat: str | None, limit: int | None, store: str | None,
             method: str,
             training: str, threads: int, provider: str, bound_table: str | None,
             report_only: bool, notes: str | None, properties: bool,
             export_scores: str | None,
             import_scores: str | None, progress: bool | None, executor: str,
             address: str | None, workers: int | None) -> None:
    """Render every camera's chart, predict its ΔmAP, emulate it on COCO and measure ΔmAP.

    \b
    Example:
      fidelity validate --cameras cameras --models yolox_nano.onnx,yolo11n.onnx@250 \\
          --images coco/val2017 --annotations instances.json --out reports/validation
      (rerun the same line to resume; add --report-only to rebuild the report)
      fidelity validate --properties --cameras cameras/properties ... --out reports/validation
      (cameras with lenses and sensors: the verdict's combined loss against the measured)
      fidelity validate --export-scores v.scores.json.gz --annotations instances.json
      fidelity validate --import-scores v.scores.json.gz --store NEWDIR   (another machine)
    """
    if transfer_scores(ValidationStore, store or str(default_store()), "--store",
                       export_scores, import_scores, annotations):
        return
    if out is None:
        raise click.UsageError("--out is needed (except with --export-scores and "
                               "--import-scores)")
    camera_inputs: dict[str, Path | str | None] = {"--cameras": cameras}
    if cameras is not None and Path(cameras).is_dir():
        camera_inputs = {f"--cameras ({p.name})": f for p in sorted(Path(cameras).iterdir())
                         for f in camera_files(p)
                         if p.suffix.lower() in (".toml", ".yaml", ".yml")}
    names = (PROPERTY_FILES if properties else
             ("validation.md", "validation.html", "validation.json", DOMAIN_FILE))
    check_outputs({f"--out ({n})": Path(out) / n for n in names},
                  {"--notes": notes, "--annotations": annotations, "--images": images,
                   "--table": bound_table, **camera_inputs, **model_inputs(models)},
                  stores={"--store": store or default_store()})
    if method not in EMULATION_METHODS:
        raise unknown_name("emulation method", method, EMULATION_METHODS)
    if training not in TRAINING_SETS:
        raise unknown_name("training set", training, TRAINING_SETS)
    if cameras is None:
        cameras = str(resource_dir("cameras"))
    cases = load_suite(cameras, cat)
    store_dir = store or str(default_store())
    if report_only:
        st = ValidationStore(store_dir, create=False)
        if annotations:  # cells stored without rest-of-run scores or bootstrap draws

            coco = load_annotations(annotations)
            st.rescore_folds(coco, lambda m: click.echo(m, err=True))
            st.score_draws(coco, lambda m: click.echo(m, err=True))
    else:
        if not models or not images or not annotations:
            raise InvalidValueError("--models, --images and --annotations are needed "
                                    "(except with --report-only)")
        specs = list(models)
        options = executor_from(executor, address, workers, threads, provider)
        specs = list(cap_models(specs, limit))
        st = run_validation(cases, specs, images, annotations, store_dir, method=method,
                            training=training, threads=threads, provider=provider,
                            progress=show_progress(progress), executor=options)

        last = st.meta().get("last_run") or {}
        if last.get("items"):
            click.echo(run_summary(last), err=True)

    if properties:
        presults = collect_property_results(st, cases)
        written = write_property_report(presults, out)
        written.append(write_json_atomic(Path(out) / PROPERTIES_DOMAIN_FILE, {
            "source": "fidelity validate --properties: the cameras the sharpness and noise "
                      "verdict was validated on and their noise, optics and vignetting (the "
                      "validity domain's 'properties', shipped in "
                      "fidelity/data/validation-domain.json)",
            **validated_properties(presults, cases).to_json()}))
        for p in written:
            click.echo(f"wrote {p}")
        a = presults.summary["dmap_points"]["all"] if presults.rows else None
        click.echo(f"{len(presults.rows)} (camera, model) cells"
                   + ("" if a is None else
                      f"; the verdict's combined ΔmAP bounds {a['within']} of {a['cells']}, "
                      f"median over-prediction {number(a['median_ratio'])}x"))
        return
    results = collect_results(st, bound_table=bound_table, suite=cases)
    paths = write_validation_report(
        results, out, notes=Path(notes).read_text(encoding="utf-8") if notes else None)

    paths.append(write_json_atomic(Path(out) / DOMAIN_FILE, {
        "source": "fidelity validate: the cameras validated, their illuminants and the kinds "
                  "of their stages (the validity domain a check's prediction is judged in; "
                  "shipped as fidelity/data/validation-domain.json)",
        **validated_cameras(results, cases).to_json()}))
    s = results.summary
    mean = s.classes["all"]
    click.echo(f"{len(results.rows)} (camera, model) cells; bound table {s.bound_table}: "
               f"mAP within bound for {mean.cameras_within}/{mean.cameras} cameras")
    for p in paths:
        click.echo(f"wrote {p}")
