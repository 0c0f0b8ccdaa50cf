"""What a command line knows of its ``--evidence`` files before a run: the format of each
(:data:`EVIDENCE_FORMATS`, by the file's suffix, checked when the option is read) and the
command line's ``invocation`` record.

Kept apart from :mod:`fidelity.report.evidence`, which writes the records and imports every
result record it renders, so that reading the options of a command (and a run without
``--evidence``) loads none of that; :mod:`fidelity.report.evidence` re-exports both names.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import display_path, file_sha256

PathArg = str | os.PathLike[str]


#: The formats of ``--evidence FILE``, chosen by the file's suffix, and what each holds.
EVIDENCE_FORMATS: Mapping[str, str] = {
    ".json": "the credibility record (JSON, schema evidence.schema.json)",
    ".srmd": "SSP Traceability Simulation Resource Meta Data: the run as a resource, every "
             "input and result with its SHA3-256, the verdicts, ΔE00, predictions, validity",
    ".stmd": "SSP Traceability Simulation Task Meta Data: the evaluation (validation) phase "
             "of a Credible Simulation Process",
    ".xqar": "ASAM Quality Checker result: a checker per subject, failed or undecided "
             "verdicts and answers outside the validity domain as issues",
}

#: The Python module each format's writer needs, and the extra that installs it.
_NEEDS = {".srmd": ("lxml", "ssp"), ".stmd": ("lxml", "ssp"), ".xqar": ("qc_baselib", "qc")}


def evidence_format(path: PathArg) -> str:
    """The format of an ``--evidence`` file: its suffix in :data:`EVIDENCE_FORMATS`
    (``.json``, ``.srmd``, ``.stmd``, ``.xqar``, any case). An unknown suffix, or a format whose
    library is missing (the ``ssp`` or ``qc`` extra), is an :class:`InvalidValueError`
    naming the file."""
    suffix = Path(path).suffix.lower()
    if suffix not in EVIDENCE_FORMATS:
        raise InvalidValueError(
            f"{display_path(path)}: --evidence writes {', '.join(EVIDENCE_FORMATS)} (by the "
            f"file's suffix), not {repr(suffix) if suffix else 'a file without one'}")
    need, extra = _NEEDS.get(suffix, (None, None))
    if need is not None and importlib.util.find_spec(need) is None:
        raise InvalidValueError(f"{display_path(path)}: writing {suffix} needs {need}: pip "
                                f"install 'camera-fidelity[{extra}]'")
    return suffix


def invocation_record(argv: Sequence[str], settings: PathArg | None = None,
                      cwd: PathArg | None = None) -> dict[str, Any]:
    """``invocation``: the command line ``argv`` (after ``fidelity``), the folder it ran in
    (default: the current one) and the settings file read (path and SHA-256; None)."""
    folder = os.fsdecode(cwd) if cwd is not None else os.getcwd()
    read = None
    if settings is not None:
        path = os.path.abspath(os.path.join(folder, os.fsdecode(settings)))
        try:
            digest: str | None = file_sha256(path)
        except OSError:
            digest = None
        read = {"path": path, "sha256": digest}
    return {"argv": [os.fsdecode(a) for a in argv], "cwd": folder, "settings": read}


__all__ = ["EVIDENCE_FORMATS", "evidence_format", "invocation_record"]
