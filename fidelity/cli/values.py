"""What option values become: the criterion, the decision rule, the detectors and COCO inputs,
the executor and the ``--measure`` request, each checked the same way in every command."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from fidelity.cli.context import from_settings, show_progress
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import check_outputs, file_sha256, require_file
from fidelity.prediction.verdict import Criterion, DecisionRule

if TYPE_CHECKING:
    from typing import TypeAlias

    from fidelity.coco.executor import ExecutorOptions
    from fidelity.coco.measure import CocoInputs
    from fidelity.coco.scores import ScoresTransfer
    from fidelity.coco.store import ResultsStore
    from fidelity.coco.sweep import ModelSpec
    from fidelity.prediction.verdict import Criterion

    # click >= 8.2 types ParamType by its value; the project supports click 8.1 too
    ParamTypeBase: TypeAlias = click.ParamType[Any]
else:
    ParamTypeBase = click.ParamType


def parse_models(text: str, what: str = "--models") -> tuple[ModelSpec, ...]:
    """``A.onnx,B.onnx@250`` -> :class:`fidelity.coco.sweep.ModelSpec` each (at least one)."""
    from fidelity.coco.sweep import ModelSpec  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    specs = tuple(ModelSpec.parse(m.strip()) for m in text.split(",") if m.strip())
    if not specs:
        raise InvalidValueError(f"{what} {text!r}: names no ONNX file")
    return specs


def cap_models(models: Sequence[ModelSpec], limit: int | None) -> tuple[ModelSpec, ...]:
    """Each model with ``--limit`` applied: its own ``@N`` or ``limit``, the smaller."""
    if limit is None:
        return tuple(models)
    return tuple(replace(s, limit=min(s.limit or limit, limit)) for s in models)


def model_inputs(models: Sequence[ModelSpec] | None) -> dict[str, Path]:
    """What ``--models`` reads, for :func:`fidelity.core.fileio.check_outputs`: each model file."""
    return {f"--models ({s.path})": s.path for s in models or ()}


def coco_inputs(images: str | None, annotations: str | None,
                models: Sequence[ModelSpec] | None, *, what: str = "--measure") -> CocoInputs:
    """:func:`fidelity.coco.measure.resolve_coco_inputs` of the options' values (those not
    given from the shared data folder)."""
    from fidelity.coco.measure import resolve_coco_inputs  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    items = None if models is None else [f"{s.path}@{s.limit}" if s.limit else str(s.path)
                                         for s in models]
    return resolve_coco_inputs(images, annotations, items, what=what)


def transfer_scores(store_type: type[ResultsStore], folder: str, option: str,
                    export_to: str | None, import_from: str | None, annotations: str | None,
                    scorer: str = "auto") -> bool:
    """Do ``--export-scores`` / ``--import-scores`` (:func:`scores_options`) on the store of
    kind ``store_type`` in ``folder`` (named by ``option`` in errors); whether either was
    given (the command then has nothing else to do)."""
    from fidelity.coco import scores  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    if export_to and import_from:
        raise click.UsageError("--export-scores and --import-scores: one at a time")
    if import_from:
        require_file(import_from, "--import-scores")
        doc = scores.read_scores(import_from, store_type)  # before a store is made
        store = store_type(folder)
        sha = file_sha256(import_from)
        if any(s.get("sha256") == sha for s in store.meta().get("imported") or []):
            click.echo(f"{import_from} is already imported into {store.path}; nothing to do")
            return True
        t = scores.import_scores(store, import_from, doc)
        if not t.cells:
            click.echo(f"{store.path} holds every cell of {import_from}; nothing to do")
            return True
        click.echo(f"{_moved(t)} imported into {store.path}; rerun the command line with "
                   f"{option} {folder} to resume")
        return True
    if export_to:
        if not annotations:
            raise click.UsageError("--export-scores needs --annotations (the fold and bootstrap "
                                   "scores are computed against them)")
        from fidelity.coco.scoring import load_annotations  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        store = store_type(folder, create=False)
        check_outputs({"--export-scores": export_to},
                      {"--annotations": annotations, f"{option} ({store.store_name})": store.path,
                       option: Path(folder)})
        t = scores.export_scores(store, load_annotations(annotations), export_to, method=scorer)
        click.echo(f"{_moved(t)} exported to {t.path} (sha256 {t.sha256[:12]})")
        return True
    return False


def _moved(t: ScoresTransfer) -> str:
    per = ", ".join(f"{m} {n}" for m, n in sorted(t.models.items()))
    unreachable = f", {t.unreachable} of them unreachable" if t.unreachable else ""
    return f"{t.cells} cells of a {t.kind} store ({per}{unreachable})"


def executor_from(executor: str, address: str | None, workers: int | None,
                  threads: int | None, provider: str) -> ExecutorOptions:
    """The :class:`fidelity.coco.executor.ExecutorOptions` of the command-line values."""
    from fidelity.coco.executor import ExecutorOptions  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    return ExecutorOptions(executor, address, workers, threads, provider)


def make_criterion(max_delta_e: float | None, max_dmap: float | None, cls: str | None,
                   unit: str) -> Criterion:
    """The criterion of ``--max-delta-e`` / ``--max-dmap`` (exactly one), ``--class`` and
    ``--unit`` (gate, compare)."""
    if (max_delta_e is None) == (max_dmap is None):
        raise click.UsageError("give exactly one of --max-delta-e X or --max-dmap P")
    if max_delta_e is not None:
        if cls is not None:
            raise click.UsageError("--class goes with --max-dmap, not --max-delta-e")
        return Criterion("max-delta-e", float(max_delta_e))
    return Criterion("max-dmap", float(max_dmap), cls or "all", unit)  # type: ignore[arg-type]


def decision_rule(decision: str, coverage_factor: float, strict: bool) -> DecisionRule:
    """The :class:`~fidelity.prediction.verdict.DecisionRule` of ``--decision``,
    ``--coverage-factor`` and ``--strict`` (:func:`fidelity.cli.options.judge_options`)."""
    if strict and decision != "guarded":
        raise click.UsageError("--strict goes with --decision guarded")
    return DecisionRule(decision, float(coverage_factor), bool(strict))


def measure_inputs(images: str | None, annotations: str | None, models: str | None
                   ) -> dict[str, Any]:
    """What ``--measure`` reads, for :func:`fidelity.core.fileio.check_outputs`: the image folder,
    the annotations and each model file (``models`` read as :class:`ModelList` reads it)."""
    specs = None if models is None else parse_models(models)
    return {"--images": images, "--annotations": annotations} | model_inputs(specs)


def measure_request(measure: bool, images: str | None, annotations: str | None,
                    models: str | None, limit: int | None) -> Any:
    """The :class:`fidelity.coco.measure.MeasureRequest` of the ``--measure`` options (None
    without ``--measure``; the other options then must not be given)."""
    if not measure:
        if any(v is not None for v in (images, annotations, models, limit)) and not all(
                from_settings(n) for n, v in (("images", images), ("annotations", annotations),
                                              ("models", models), ("limit", limit))
                if v is not None):
            raise click.UsageError("--images, --annotations, --models and --limit go with "
                                   "--measure")
        return None
    from fidelity.coco.measure import MeasureRequest, resolve_coco_inputs  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    return MeasureRequest(resolve_coco_inputs(images, annotations, models), limit=limit,
                          progress=show_progress(None))


__all__ = [
    "cap_models",
    "coco_inputs",
    "decision_rule",
    "executor_from",
    "make_criterion",
    "measure_inputs",
    "measure_request",
    "model_inputs",
    "parse_models",
    "transfer_scores",
]
