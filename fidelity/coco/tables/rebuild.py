"""Rebuild a shipped table's rows from the scores files it names, and compare them.

A measured table (the colour prediction tables ``coco1000-measured``, ``coco1000-directional``
and the property tables ``coco1000-sharpness``, ``coco1000-noise``) names in
``provenance.scores_files`` the committed scores files (``fidelity sweep --export-scores``)
it is rebuilt from, each by its path in the source checkout and its SHA-256
(:func:`fidelity.coco.scores.scores_file_entry`). :func:`rebuild_table` imports them into a
temporary sweep store and makes the table of the same kind again (what ``fidelity tables
FILE...`` writes); :func:`row_differences` lists every row whose numbers differ between the
shipped table and the rebuilt one. That is the last link of ``fidelity verify --chain``
(record -> table -> scores file -> rows).

A row is one point of a curve (a prediction table: per size class or model, per transform
family for the direction-aware table, at one chart ΔE00) or one cell of a property table
(per model, per degradation family and level); its numbers are every column but the words
(``source``). The comparison is exact (the rebuilt document is written and read as JSON, as
the shipped one was); without the COCO annotations the standard errors (``*_se``) cannot be
computed again and are left out of it (:func:`row_differences` ``standard_errors=False``).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from fidelity.coco.scores import import_scores, read_scores
from fidelity.coco.sweep import SweepStore
from fidelity.coco.tables.colour import tables_result
from fidelity.coco.tables.degradation import property_tables
from fidelity.coco.tables.directional import directional_table
from fidelity.coco.tables.prediction import prediction_table
from fidelity.core.fileio import json_ready

#: The words of a row, which are not compared (a size class's ``source`` lists its models in
#: the store's order).
WORDS = ("source",)

RowKey = tuple[Any, ...]


def table_rows(doc: Mapping[str, Any]) -> dict[RowKey, dict[str, Any]]:
    """The rows of a table document (module docstring), by key: ``("curve", size, model,
    ΔE)`` and ``("curve", size, model, "baseline")`` (its baseline mAP and AP) for each curve,
    ``("family", family, size, model, ΔE)`` for a direction-aware table's family curves,
    ``("cell", model, family, level)`` for a property table's cells."""
    rows: dict[RowKey, dict[str, Any]] = {}

    def curve(prefix: RowKey, c: Mapping[str, Any]) -> None:
        where = (*prefix, c.get("size"), c.get("model"))
        if "baseline_map" in c:
            rows[(*where, "baseline")] = {"baseline_map": c.get("baseline_map"),
                                          "baseline_ap": c.get("baseline_ap")}
        for p in c.get("points") or []:
            rows[(*where, p.get("delta_e"))] = {k: v for k, v in p.items() if k not in WORDS}

    for c in doc.get("curves") or []:
        curve(("curve",), c)
    for family, fam in (doc.get("families") or {}).items():
        for c in fam.get("curves") or []:
            curve(("family", family), c)
    if doc.get("kind") == "property-table":
        for model, m in (doc.get("models") or {}).items():
            for cell in m.get("cells") or []:
                rows[("cell", model, cell.get("family"), cell.get("level"))] = {
                    k: v for k, v in cell.items() if k not in WORDS}
    return rows


def row_name(key: RowKey) -> str:
    """A row's key as words: ``yolox_nano ΔE 3``, ``size n ΔE 1``, ``family tone yolox_nano
    ΔE 2``, ``yolox_nano gaussian-noise 0.04``."""
    if key[0] == "cell":
        return f"{key[1]} {key[2]} {key[3]:g}"
    head = f"family {key[1]} " if key[0] == "family" else ""
    size, model, at = key[-3], key[-2], key[-1]
    where = model if model else f"size {size}"
    return f"{head}{where} " + ("baseline" if at == "baseline" else f"ΔE {at:g}")


#: Two numbers of a row agree to this relative difference (:func:`row_differences`): far
#: below any digit a table is read with, far above a processor's last bits (1e-16).
ROW_RTOL = 1e-12


def _same(a: Any, b: Any) -> bool:
    """Equal, or two floats within :data:`ROW_RTOL` of each other."""
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=ROW_RTOL, abs_tol=0.0)
    return bool(a == b)


def row_differences(shipped: Mapping[str, Any], rebuilt: Mapping[str, Any], *,
                    standard_errors: bool = True) -> tuple[int, list[str]]:
    """Compare the rows of two table documents (:func:`table_rows`): the number of rows
    compared and one line per row that differs (``<row>: <column> <shipped> in the table,
    <rebuilt> rebuilt``, or a row only one of them has). Numbers are the same when they
    agree to :data:`ROW_RTOL` relative: a chart calibration measured again on another
    processor differs in its last bits. ``standard_errors`` False: the ``*_se`` columns are
    left out (a rebuild without the COCO annotations has none)."""
    a, b = table_rows(shipped), table_rows(rebuilt)
    out: list[str] = []
    for key in a:
        if key not in b:
            out.append(f"{row_name(key)}: in the table, not rebuilt")
            continue
        for column in sorted(set(a[key]) | set(b[key])):
            if not standard_errors and column.endswith("_se"):
                continue
            if not _same(a[key].get(column), b[key].get(column)):
                out.append(f"{row_name(key)}: {column} {a[key].get(column)!r} in the table, "
                           f"{b[key].get(column)!r} rebuilt")
    out += [f"{row_name(key)}: rebuilt, not in the table" for key in b if key not in a]
    return len(a), out


def table_kind(doc: Mapping[str, Any]) -> str:
    """``"directional"``, ``"measured"`` or ``"property"``: which builder makes the table
    ``doc``; raises ValueError for a table no sweep makes (published bounds)."""
    if doc.get("kind") == "property-table":
        return "property"
    if doc.get("kind") == "directional" or (doc.get("kind") == "measured"
                                            and doc.get("families")):
        return "directional"
    if doc.get("kind") == "measured":
        return "measured"
    raise ValueError(f"a {doc.get('kind')} table is not rebuilt from scores files")


def rebuild_table(doc: Mapping[str, Any], scores: Sequence[str | os.PathLike[str]],
                  coco: Any = None, *, cache: dict[Any, Any] | None = None) -> dict[str, Any]:
    """The table ``doc`` made again from the scores files ``scores`` (imported in turn into a
    temporary sweep store, as ``fidelity tables FILE...`` does).

    Parameters
    ----------
    doc
        The shipped table's document (its ``kind``, ``name``, and ``property`` for a property
        table, choose what is built: :func:`table_kind`).
    scores
        The scores files, in the order the table's ``provenance.scores_files`` names them.
    coco
        The sweep's COCO annotations (pycocotools ``COCO``), for the standard errors; None:
        rebuilt without them.
    cache
        A dict kept between calls: the sharpness and noise tables are built together (the
        chart calibrated once) and the second is taken from it.

    Returns
    -------
    dict
        The rebuilt table's document, as written to JSON and read back.
    """
    kind = table_kind(doc)
    key = (kind == "property", tuple(str(Path(p).resolve()) for p in scores), id(coco))
    if cache is not None and kind == "property" and key in cache:
        return _property_doc(cache[key], doc)
    with tempfile.TemporaryDirectory(prefix="fidelity-chain-") as folder:
        store = SweepStore(Path(folder) / "store")
        try:
            for path in scores:
                import_scores(store, path, read_scores(path, SweepStore))
            if kind == "property":
                prop = str(doc.get("property"))
                stem = str(doc.get("name") or "coco1000").removesuffix(f"-{prop}")
                built = property_tables(store, coco, name=stem)
                if cache is not None:
                    cache[key] = built
                return _property_doc(built, doc)
            else:
                tables = tables_result(store, coco).tables
                name = str(doc.get("name") or "coco1000-measured")
                made = (directional_table(tables, name) if kind == "directional"
                        else prediction_table(tables, name))
        finally:
            store.close()
    rebuilt: dict[str, Any] = json.loads(json.dumps(json_ready(made)))
    return rebuilt


def _property_doc(built: Mapping[str, Any], doc: Mapping[str, Any]) -> dict[str, Any]:
    """The table of ``doc``'s property among the property tables ``built``, as JSON."""
    prop = str(doc.get("property"))
    if prop not in built:
        raise ValueError(f"the scores files hold no {prop} cells")
    rebuilt: dict[str, Any] = json.loads(json.dumps(json_ready(built[prop].to_json())))
    return rebuilt


__all__ = ["ROW_RTOL", "WORDS", "rebuild_table", "row_differences", "row_name", "table_kind",
           "table_rows"]
