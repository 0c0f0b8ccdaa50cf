"""The files a credibility record (:mod:`fidelity.report.evidence`) names: what its SSP
Traceability files trace (:mod:`fidelity.report.ssp`) and what ``fidelity verify`` hashes again
(:mod:`fidelity.report.verify`). A module of its own: the evidence writers import the SSP
writer, which reads the record's files here."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any


def record_files(record: Mapping[str, Any]
                 ) -> Iterator[tuple[str, str, Mapping[str, Any]]]:
    """The files a credibility record names, as ``(kind, name, entry)`` with the entry's
    recorded ``path`` and ``sha256``: each subject's input files (``input``, its role), its
    prediction table (``prediction table``, the table's name) and that table's
    ``calibration table``; then the ``settings`` ``file`` read; then each fit's written files
    (``output``, the file's key). Inputs without a path (render settings) are no file. A file
    several subjects name comes once per subject: the callers decide what counts as the
    same."""
    subjects = record.get("subjects") or []
    for subject in subjects:
        for item in subject.get("inputs") or []:
            if item.get("path") is not None:
                yield "input", item["role"], item
        table = subject.get("prediction_table")
        if table:
            yield "prediction table", table["name"], table
            calibration = table.get("calibration")
            if calibration:
                yield "calibration table", calibration.get("name") or "calibration", calibration
    settings = (record.get("invocation") or {}).get("settings")
    if settings:
        yield "settings", "file", settings
    for subject in subjects:
        for name, item in ((subject.get("correction") or {}).get("files") or {}).items():
            yield "output", name, item


__all__ = ["record_files"]
