"""``fidelity dataset``: write transformed copies of an image folder."""

from __future__ import annotations

from pathlib import Path

import click

from fidelity.cli.context import show_progress
from fidelity.cli.options import Targets, TransformNames, common_options, progress_option
from fidelity.coco.dataset import list_images, subset_name, write_grid, write_transformed_dataset
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import check_output_folders
from fidelity.pipeline.environment import available_cpus


@click.command()
@click.option("--images", required=True, type=click.Path(file_okay=False),
              help="Folder of original JPEGs (never modified).")
@click.option("--out", required=True, type=click.Path(file_okay=False),
              help="Output folder; one subfolder per (transform, ΔE).")
@click.option("--transforms", type=TransformNames(), default=None,
              help="Transform name, or 'all' / comma-separated names (grid form).")
@click.option("--targets", type=Targets(baseline=True), default=None,
              help="Chart ΔE target, or comma-separated targets or ranges a-b (grid form); "
                   "0 = baseline.")
@click.option("--param", type=float, default=None,
              help="Use this transform parameter instead of the calibrated one (single cell).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Parallel worker processes (default: one per CPU core this process may use).")
@progress_option
@common_options
def dataset(images: str, out: str, transforms: list[str] | None, targets: list[float] | None,
            param: float | None, workers: int | None, progress: bool | None) -> None:
    """Write transformed JPEGs (original quantization tables and subsampling); reruns resume."""
    if workers is None:
        workers = available_cpus()

    if transforms is None or targets is None:
        raise InvalidValueError("give --transforms and --targets (e.g. --transforms "
                                "contrast-inc --targets 3, or --transforms all --targets "
                                "0,1,2,3)")
    files = list_images(images)
    names, values = transforms, targets

    check_output_folders({f"--out ({subset_name(t, e)})": Path(out) / subset_name(t, e)
                          for t in names for e in values}, {"--images": images})
    bars = show_progress(progress)
    if len(names) == 1 and len(values) == 1:
        res = [write_transformed_dataset(files, out, names[0], values[0], param=param,
                                         workers=workers, progress=bars)]
    else:
        if param is not None:
            raise InvalidValueError("--param applies to a single (transform, ΔE) cell only")
        res = write_grid(files, out, names, values, workers=workers, progress=bars)
    for r in res:
        if "skipped_reason" in r:
            click.echo(f"{r['subset']}: skipped: {r['skipped_reason']}")
        else:
            p = "-" if r["param"] is None else f"{r['param']:.6g}"
            click.echo(f"{r['subset']}: param {p}, wrote {r['written']}, kept {r['skipped']} "
                       f"existing, {r['seconds']:.1f} s")
