"""Where a sweep's tables come from: the store's provenance, and the runs a merge keeps.

The provenance (``meta`` table) of a sweep store is checked against
:data:`SWEEP_META_SCHEMA` (:func:`check_store_meta`); the words of the COCO scorers
(:func:`scorer_words`) and of the standard errors (:data:`STANDARD_ERROR_WORDS`) go into the
measured prediction table's provenance and the reports; the records of the runs that measured
a kept model (:func:`earlier_runs`, :func:`runs_passed_on`) follow it through merges
(:func:`fidelity.coco.tables.build.merge_tables`).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from fidelity.coco.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
from fidelity.core import schema as sc

#: How each standard-error method was computed (provenance and reports).
STANDARD_ERROR_WORDS: dict[str, str] = {
    "larger": f"the larger, per cell, of the paired image bootstrap of the whole-run loss "
              f"({BOOTSTRAP_RESAMPLES} draws of the images with replacement, seed "
              f"{BOOTSTRAP_SEED}) and the leave-one-fold-out jackknife over 5 interleaved image "
              "folds (fidelity.coco.loss.loss_estimate; each understates alone in some regime, "
              "reports/validation/standard_error.md)",
    "bootstrap": f"paired image bootstrap of the whole-run loss, {BOOTSTRAP_RESAMPLES} draws of "
                 f"the images with replacement, seed {BOOTSTRAP_SEED}, baseline and cell scored "
                 "on the same draws "
                 "(fidelity.coco.bootstrap.draw_scores, fidelity.coco.loss."
                 "bootstrap_standard_error)",
    "jackknife": "leave-one-fold-out jackknife of the whole-run loss over 5 interleaved image "
                 "folds (fidelity.coco.loss.jackknife_standard_error; measured before the "
                 "bootstrap; larger than the bootstrap on 1000-image cells, "
                 "reports/validation/standard_error.md)",
    "folds": "paired SE of the per-fold losses over 5 interleaved image folds (measured before "
             "the jackknife; understates the SE of the whole-run loss, "
             "reports/validation/standard_error.md)",
    "mixed": "more than one of these methods over the model's cells",
}


def scorer_words(scorers: Sequence[Mapping[str, Any]] | None) -> str:
    """Which COCO scorers scored the store's cells, in words."""
    if not scorers:
        return "pycocotools"
    parts = [f"{e['scorer']}" + (f" from {e['since']}" if e.get("since") else "")
             for e in scorers]
    return ", then ".join(parts)


#: What a kept model's measurement record holds of the tables' meta that measured it.
RUN_KEYS = ("versions", "machine", "machines", "scorers", "imported")


def record_by_name(record: Mapping[str, Any]) -> dict[str, Any]:
    """A file record (``file``, ``sha256``) with its file by name alone: tables of older
    versions recorded a path on their machine, which names the machine, not the data."""
    return dict(record) | ({"file": Path(str(record["file"])).name} if record.get("file") else {})


def earlier_runs(prev: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The measurement records an earlier merge kept (``runs``); a record of an older version,
    one for all its kept models with at most one ``via``, as one run."""
    if not prev:
        return []
    if "runs" in prev:
        return [dict(r) for r in prev["runs"]]
    via = prev.get("via")
    run = {k: v for k, v in record_by_name(prev).items() if k != "via"}
    return [run | ({"via": [record_by_name(via)]} if via else {})]


def runs_passed_on(runs: Sequence[Mapping[str, Any]], models: Sequence[str],
                   via: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The ``runs`` that measured some of ``models``, each narrowed to those, with ``via``
    (files passed through since, newest last) extended."""
    passed = []
    for run in runs:
        mine = [m for m in models if m in (run.get("models") or ())]
        if mine:
            through = [*(run.get("via") or []), *via]
            passed.append(dict(run) | {"models": mine} | ({"via": through} if through else {}))
    return passed


def _names(kind: str) -> sc.Node:
    return sc.ListOf(sc.String(), describe=f"a list of {kind} names")


#: The provenance (``meta`` table) of a sweep store as ``fidelity sweep`` writes it and the
#: reports read it: each value is JSON; only the keys read are checked, others pass.
SWEEP_META_SCHEMA = sc.Table(fields=(
    sc.Field("grid", sc.Table(fields=(
        sc.Field("transforms", _names("transform")),
        sc.Field("targets", sc.ListOf(sc.Number(lo=0.0), describe="a list of ΔE values >= 0")),
        sc.Field("models", _names("model")),
    ), extra=True)),
    sc.Field("data", sc.Table(fields=(
        sc.Field("images", sc.String(nullable=True)),
        sc.Field("annotations", sc.String(nullable=True)),
        sc.Field("image_count", sc.Integer(lo=0, nullable=True)),
    ), extra=True)),
    sc.Field("scorers", sc.ListOf(sc.OneOf(options=(
        sc.String(), sc.Table(fields=(sc.Field("scorer", sc.String(), required=True),
                                      sc.Field("since", sc.String(nullable=True))),
                              extra=True)), describe="a scorer name or {scorer, since}"))),
    sc.Field("versions", sc.MapOf(nullable=True)),
    sc.Field("versions_seen", sc.ListOf(sc.MapOf(nullable=True), nullable=True)),
    sc.Field("machine", sc.MapOf(nullable=True)),
    sc.Field("machines", sc.ListOf(sc.MapOf(), nullable=True)),
    sc.Field("imported", sc.ListOf(sc.Table(fields=(
        sc.Field("file", sc.String(), required=True),
        sc.Field("sha256", sc.String(), required=True),
    ), extra=True), describe="the scores files imported (file, sha256, ...)")),
), extra=True)


def check_store_meta(db: Any, path: str, schema: sc.Node = SWEEP_META_SCHEMA) -> None:
    """Check a results store's provenance (its ``meta`` table, read through the open SQLite
    connection ``db``; nothing is written) against ``schema``: every value JSON, the keys the
    reports read of the right shape. Raises :class:`~fidelity.core.schema.SchemaError`
    ``<store> (provenance): <key>: <problem>``."""
    origin = f"{path} (provenance)"
    try:
        rows = list(db.execute("SELECT key, value FROM meta"))
    except sqlite3.DatabaseError as exc:
        raise sc.SchemaError(f"{origin}: cannot read: {exc}") from None
    meta: dict[str, Any] = {}
    for key, value in rows:
        meta[str(key)] = sc.parse_text(str(value), "json", f"{origin}: {key}")
    sc.validate(meta, schema, origin)


__all__ = [
    "RUN_KEYS",
    "STANDARD_ERROR_WORDS",
    "SWEEP_META_SCHEMA",
    "check_store_meta",
    "earlier_runs",
    "record_by_name",
    "runs_passed_on",
    "scorer_words",
]
