"""``fidelity verify --chain``: walk a credibility record to the raw data behind its tables.

A record (:mod:`fidelity.report.evidence`) names each subject's prediction table (and the
sharpness and noise tables it judged with) by path and SHA-256; a measured table names the
committed scores files its rows are rebuilt from (``provenance.scores_files``: path in the
source checkout, SHA-256, detectors). :func:`chain_findings` checks each link in turn, as a
:class:`~fidelity.report.verify.Finding` of kind ``chain``:

1. **table**: the table file here has the SHA-256 the record holds;
2. **scores file**: each scores file the table names is here (by its path from the folder
   the run started in, the record's folder, or the source checkout) with the SHA-256 the table
   holds;
3. **rows**: the rows made again from those scores files
   (:func:`fidelity.coco.tables.rebuild.rebuild_table`) are the table's, every number
   exactly (:func:`~fidelity.coco.tables.rebuild.row_differences`); the standard errors too
   when the sweep's COCO annotations are at hand (``annotations``, else the shared data's
   copy of the file the table's provenance names).

A link that does not hold is ``broken`` (verify exits 1) and the links after it are not
walked; a table that names no scores files (published bounds) has nothing to rebuild
(``not rebuilt``, reported, not failed).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path, PurePath
from typing import Any

from fidelity.coco.scoring import load_annotations
from fidelity.coco.tables.rebuild import rebuild_table, row_differences
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import display_path, file_sha256
from fidelity.core.resources import shared_dir
from fidelity.report.verify import Finding, locate

#: The most differing rows a ``rows`` finding names (then how many more).
SHOWN_DIFFERENCES = 3


def chain_tables(doc: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The tables a record's chain starts from, each once: every subject's prediction table
    and the property tables it names (``subjects[].property_tables``) and its direction-aware
    table (``subjects[].directional_table``), as the record holds
    them (``name``, ``path``, ``sha256``)."""
    out: list[dict[str, Any]] = []
    seen: set[tuple[Any, Any]] = set()
    for subject in doc.get("subjects") or []:
        for table in [subject.get("prediction_table"), *(subject.get("property_tables") or []),
                      subject.get("directional_table")]:
            if not isinstance(table, Mapping) or not table.get("name"):
                continue
            key = (table.get("path"), table.get("sha256"))
            if key not in seen:
                seen.add(key)
                out.append(dict(table))
    return out


def annotations_for(provenance: Mapping[str, Any],
                    given: str | os.PathLike[str] | None = None) -> Path | None:
    """The COCO annotations a table's standard errors are rebuilt with: ``given``, else the
    shared data's ``coco/annotations/<name>`` of the file the table's provenance names
    (``images.annotations``, or ``store.data.annotations`` of a property table), if there."""
    if given is not None:
        return Path(given)
    named = ((provenance.get("images") or {}).get("annotations")
             or (((provenance.get("store") or {}).get("data")) or {}).get("annotations"))
    shared = shared_dir()
    if not named or shared is None:
        return None
    candidate = shared / "coco" / "annotations" / PurePath(str(named)).name
    return candidate if candidate.is_file() else None


def _link(table: str, link: str, status: str, detail: str, path: str | None = None
          ) -> Finding:
    return Finding("chain", f"{table} -> {link}", status, detail, path)


def table_chain(table: Mapping[str, Any], cwd: str | None, record_dir: Path,
                annotations: str | os.PathLike[str] | None = None,
                cache: dict[Any, Any] | None = None) -> list[Finding]:
    """The chain of one table the record names (module docstring): one finding per link,
    up to the first broken one; ``cache``: kept between the tables of one record (the
    annotations loaded once, the sharpness and noise tables rebuilt together)."""
    name = str(table.get("name"))
    recorded, digest = table.get("path"), table.get("sha256")
    found = locate(str(recorded), cwd, record_dir) if recorded else None
    if found is None:
        return [_link(name, "table", "broken", f"{display_path(str(recorded or ''))[:300]}: "
                      "not there (no such file)")]
    now = file_sha256(found)
    if digest is None or now != digest:
        was = f"recorded {digest[:12]}" if digest else "the record holds no SHA-256"
        return [_link(name, "table", "broken", f"SHA-256 {now[:12]}, {was}",
                      display_path(found))]
    out = [_link(name, "table", "linked", f"SHA-256 {now[:12]} as recorded",
                 display_path(found))]
    try:
        doc = json.loads(found.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return [*out, _link(name, "scores file", "broken", f"the table cannot be read: {exc}")]
    provenance = doc.get("provenance") or {}
    entries = [e for e in provenance.get("scores_files") or [] if isinstance(e, Mapping)]
    if not entries:
        return [*out, _link(name, "scores file", "not rebuilt",
                            "the table names no scores files (published bounds, or a table "
                            "of an earlier layout): its rows are not rebuilt")]
    scores: list[Path] = []
    for entry in entries:
        where = str(entry.get("path"))
        label = f"scores file {PurePath(where).name}"
        path = locate(where, cwd, record_dir)
        if path is None:
            return [*out, _link(name, label, "broken", "not there: the scores files are in "
                                "the source checkout (reports/coco/...), not in a wheel")]
        sha = file_sha256(path)
        if sha != entry.get("sha256"):
            return [*out, _link(name, label, "broken", f"SHA-256 {sha[:12]}, the table holds "
                                f"{str(entry.get('sha256'))[:12]}", display_path(path))]
        out.append(_link(name, label, "linked", f"SHA-256 {sha[:12]} as the table holds "
                         f"({', '.join(entry.get('models') or [])})", display_path(path)))
        scores.append(path)
    return [*out, _rows_link(name, doc, scores, annotations_for(provenance, annotations),
                             {} if cache is None else cache)]


def _rows_link(name: str, doc: Mapping[str, Any], scores: list[Path],
               annotations: Path | None, cache: dict[Any, Any]) -> Finding:
    try:
        coco = None
        if annotations is not None:
            key = ("annotations", str(annotations))
            if key not in cache:
                cache[key] = load_annotations(annotations)
            coco = cache[key]
        rebuilt = rebuild_table(doc, scores, coco, cache=cache)
    except (FidelityError, ValueError, KeyError, TypeError) as exc:
        return _link(name, "rows", "broken", f"not rebuilt from the scores files: {exc}")
    n, differ = row_differences(doc, rebuilt, standard_errors=coco is not None)
    with_se = ("standard errors included" if coco is not None else
               "standard errors not compared: no COCO annotations (give --annotations)")
    if not differ:
        return _link(name, "rows", "linked", f"{n} rows rebuilt from {len(scores)} scores "
                     f"file(s), every number the table's ({with_se})")
    more = len(differ) - SHOWN_DIFFERENCES
    shown = "; ".join(differ[:SHOWN_DIFFERENCES]) + (f"; and {more} more" if more > 0 else "")
    return _link(name, "rows", "broken", f"{len(differ)} of {n} rows differ from the scores "
                 f"files' ({with_se}): {shown}")


def chain_findings(doc: Mapping[str, Any], path: str | os.PathLike[str], *,
                   annotations: str | os.PathLike[str] | None = None) -> list[Finding]:
    """The chain of every table the record ``doc`` (read from ``path``) names
    (:func:`chain_tables`, :func:`table_chain`); none when it names no table."""
    cwd = (doc.get("invocation") or {}).get("cwd")
    record_dir = Path(path).resolve().parent
    out: list[Finding] = []
    cache: dict[Any, Any] = {}
    for table in chain_tables(doc):
        out += table_chain(table, cwd, record_dir, annotations, cache)
    return out


__all__ = ["SHOWN_DIFFERENCES", "annotations_for", "chain_findings", "chain_tables",
           "table_chain"]
