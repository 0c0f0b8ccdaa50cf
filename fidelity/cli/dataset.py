"""``fidelity dataset``: write transformed copies of an image folder."""

from __future__ import annotations

import click


@click.command()
@click.option("--images", required=True, type=click.Path(file_okay=False),
              help="Folder of original JPEGs (never modified).")
@click.option("--out", required=True, type=click.Path(file_okay=False),
              help="Output folder; one subfolder per (transform, ΔE).")
@click.option("--transform", "transform", default=None,
              help="Transform name, or 'all' / comma-separated names (grid form).")
@click.option("--delta-e", "delta_e", default=None,
              help="Chart ΔE target, or comma-separated targets (grid form); 0 = baseline.")
@click.option("--param", type=float, default=None,
              help="Use this transform parameter instead of the calibrated one (single cell).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Parallel worker processes (default: one per CPU core this process may use).")
@click.option("--progress/--no-progress", default=True, show_default=True)
def dataset(images: str, out: str, transform: str | None, delta_e: str | None,
            param: float | None, workers: int | None, progress: bool) -> None:
    """Write transformed JPEGs (original quantization tables and subsampling); reruns resume."""
    from fidelity.environment import available_cpus

    if workers is None:
        workers = available_cpus()
    from fidelity.cli.sweep import _targets, _transforms
    from fidelity.coco.dataset import list_images, write_grid, write_transformed_dataset
    from fidelity.errors import InvalidValueError

    if transform is None or delta_e is None:
        raise InvalidValueError("give --transform and --delta-e (e.g. --transform contrast-inc "
                                "--delta-e 3, or --transform all --delta-e 0,1,2,3)")
    files = list_images(images)
    names = _transforms(transform)
    targets = _targets(delta_e)
    if len(names) == 1 and len(targets) == 1:
        res = [write_transformed_dataset(files, out, names[0], targets[0], param=param,
                                         workers=workers, progress=progress)]
    else:
        if param is not None:
            raise InvalidValueError("--param applies to a single (transform, ΔE) cell only")
        res = write_grid(files, out, names, targets, workers=workers, progress=progress)
    for r in res:
        if "skipped_reason" in r:
            click.echo(f"{r['subset']}: skipped: {r['skipped_reason']}")
        else:
            p = "-" if r["param"] is None else f"{r['param']:.6g}"
            click.echo(f"{r['subset']}: param {p}, wrote {r['written']}, kept {r['skipped']} "
                       f"existing, {r['seconds']:.1f} s")
