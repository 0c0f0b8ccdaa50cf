"""The files a credibility record (:mod:`fidelity.report.evidence`) names: what its SSP
Traceability files trace (:mod:`fidelity.report.ssp`) and what ``fidelity verify`` hashes again
(:mod:`fidelity.report.verify`). A module of its own: the evidence writers import the SSP
writer, which reads the record's files here."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any


def record_files(record: Mapping[str, Any], *, evidence: bool = False
                 ) -> Iterator[tuple[str, str, Mapping[str, Any]]]:
    """The files a credibility record names, as ``(kind, name, entry)`` with the entry's
    recorded ``path`` and ``sha256``: each subject's input files (``input``, its role), its
    prediction table (``prediction table``, the table's name) and that table's
    ``calibration table``; then the ``settings`` and ``context`` files read; then each fit's written files
    (``output``, the file's key). With ``evidence`` (layout 1.2), each subject's evidence
    files come after its table: the ``validated cameras`` file its validity checks quote and
    the table's ``scores file`` entries (the committed files its rows rebuild from), then
    each ``property table`` (sharpness, noise) the prediction judged with and its scores
    files, and the ``directional table`` the direction-aware prediction read (its scores
    files are the prediction table's) and the ``validated bound`` the interval states (the
    model-form error's bound, :mod:`fidelity.prediction.validated`). Then the ``settings`` ``file`` and the ``context`` ``file`` (``--context``) read.
    Inputs without a path (render settings) are no file. A file several subjects name comes once per
    subject: the callers decide what counts as the same."""
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
        if not evidence:
            continue
        cameras = (subject.get("validity") or {}).get("validated_cameras")
        if cameras:
            yield "validated cameras", "validation-domain", cameras
        for scores in (table or {}).get("scores_files") or []:
            yield "scores file", ", ".join(scores.get("models") or []) or "scores", scores
        for prop in subject.get("property_tables") or []:
            yield "property table", prop.get("name") or "property", prop
            for scores in prop.get("scores_files") or []:
                yield "scores file", ", ".join(scores.get("models") or []) or "scores", scores
        bound = subject.get("validated_bound")
        if bound:
            yield "validated bound", "validated-bound", bound
        margin = subject.get("property_margin")
        if margin:
            yield "property margin", "property-margin", margin
        directional = subject.get("directional_table")
        if directional and directional.get("path"):
            yield "directional table", directional.get("name") or "directional", directional
    settings = (record.get("invocation") or {}).get("settings")
    if settings:
        yield "settings", "file", settings
    context = (record.get("context_of_use") or {}).get("file")
    if context:
        yield "context", "file", context
    for subject in subjects:
        for name, item in ((subject.get("correction") or {}).get("files") or {}).items():
            yield "output", name, item


__all__ = ["record_files"]
