"""Check the SSP Traceability files of a run against its JSON record (``fidelity verify``).

A run given ``--evidence run.json --evidence run.srmd`` writes the JSON record first and the
SRMD from it (:mod:`fidelity.report.ssp`): the SRMD lists every input and result, the JSON
record among the results, each with the SHA3-256 (FIPS 202) of its bytes, the checksum SSP
Traceability 1.0 prescribes (``checksum``, ``checksumType="SHA3-256"``). An STMD lists the
same files, and the SRMD, with theirs. :func:`ssp_findings` finds the SRMDs and STMDs the
recorded command line wrote (its ``--evidence`` files with those suffixes, from the folder it
ran in, else by name beside the record) and checks each, as one
:class:`~fidelity.report.verify.Finding` of kind ``srmd`` or ``stmd``:

- every checksum it holds against the SHA3-256 of the file now (``changed`` naming the first
  file that differs, or ``missing``);
- an SRMD's content against the record: the SRMD made again from the JSON record and the
  files and checksums it lists (:func:`fidelity.report.ssp.srmd_element`) must be the file
  byte for byte, so a value edited in it (a verdict, a ΔE00, a checksum) is ``edited``.
  (An STMD holds a random GUID: only its checksums are checked.)

Each passes as ``intact``. Reading them needs lxml (the ``ssp`` extra): without it an SRMD is
``not checked`` (reported, not failed); an SRMD the command line wrote that is not here is
``not here`` (a record handed over alone).
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import unquote_to_bytes, urlparse

from fidelity.core.fileio import display_path, file_sha3_256
from fidelity.report.verify import Finding

#: The suffixes of the SSP Traceability files checked, and the finding kind of each.
SSP_KINDS: Mapping[str, str] = {".srmd": "srmd", ".stmd": "stmd"}


def evidence_paths(argv: Sequence[str]) -> list[str]:
    """The files a recorded command line (after ``fidelity``) wrote with ``--evidence``
    (``--evidence F`` or ``--evidence=F``), in order."""
    out: list[str] = []
    for i, token in enumerate(argv):
        if token == "--evidence" and i + 1 < len(argv):
            out.append(argv[i + 1])
        elif token.startswith("--evidence="):
            out.append(token.split("=", 1)[1])
    return out


def _uri_path(uri: str, base: Path) -> Path:
    """The file an SRMD's URI names (relative to the document's folder ``base``)."""
    parsed = urlparse(uri)
    if parsed.scheme == "file":
        return Path(os.fsdecode(unquote_to_bytes(parsed.path)))
    return base / os.fsdecode(unquote_to_bytes(uri))


def _checksum_problem(entries: Sequence[tuple[str, Path, str | None]]) -> Finding | None:
    """The first listed file whose SHA3-256 is not the listed checksum, as a finding."""
    for role, path, checksum in entries:
        if checksum is None:
            continue
        try:
            now = file_sha3_256(path)
        except OSError:
            return Finding("", role, "missing", f"{role}: {display_path(path)[:300]} is not "
                           "there (its SHA3-256 is listed)")
        if now != checksum:
            return Finding("", role, "changed", f"{role} {display_path(path)[:300]}: SHA3-256 "
                           f"{now[:12]}, listed {checksum[:12]}")
    return None


def check_ssp_file(path: Path, record: Mapping[str, Any]) -> Finding:
    """Check one SRMD or STMD (module docstring) against the JSON ``record``."""
    # the [ssp] extra (lxml), which the caller checked
    from fidelity.report.ssp import (  # noqa: PLC0415
        NAMESPACES,
        TracedFile,
        read_ssp_document,
        srmd_bytes,
    )  # noqa: PLC0415

    kind = SSP_KINDS[path.suffix.lower()]
    shown = display_path(path)
    try:
        raw = path.read_bytes()
        root = read_ssp_document(raw)
    except (OSError, ValueError) as exc:
        return Finding(kind, path.name, "edited", f"not a readable {kind.upper()}: {exc}",
                       shown)
    base = path.parent
    srmd_tag = f"{{{NAMESPACES['srmd']}}}SimulationResourceMetaData"
    href = f"{{{NAMESPACES['xlink']}}}href"
    listed: list[tuple[str, Path, str | None]] = []
    files: list[TracedFile] = []
    for element in root.iter(srmd_tag):
        if element is root or element.get("data") is None:
            continue
        file_path = _uri_path(str(element.get("data")), base)
        listed.append((str(element.get("name")), file_path, element.get("checksum")))
    if kind == "srmd":
        for group in root:
            what = str(group.get("type", "")).rsplit(".", 1)[-1]
            if what not in ("inputs", "results"):
                continue
            for entry in group:
                inner = next(iter(entry), None)
                uri = entry.get(href)
                if uri is None:
                    continue
                files.append(TracedFile(
                    what.removesuffix("s"), str(entry.get("keyword")), _uri_path(uri, base),
                    inner.get("checksum") if inner is not None else None,
                    str(entry.get("linkedType"))))
    problem = _checksum_problem(listed)
    if problem is not None:
        return Finding(kind, path.name, problem.status, problem.detail, shown)
    n = sum(c is not None for _, _, c in listed)
    if kind == "srmd":
        again = srmd_bytes(dict(record), files, base)
        if again != raw:
            return Finding(kind, path.name, "edited", "its content is not what the JSON record "
                           f"and the {len(files)} files it lists make: the SRMD was edited",
                           shown)
        return Finding(kind, path.name, "intact", f"{n} SHA3-256 checksums as the files; its "
                       "content the JSON record's", shown)
    return Finding(kind, path.name, "intact", f"{n} SHA3-256 checksums as the files", shown)


def ssp_findings(doc: Mapping[str, Any], record_path: str | os.PathLike[str],
                 inputs: str | os.PathLike[str] | None = None) -> list[Finding]:
    """The checks of every SRMD and STMD the record's command line wrote (module
    docstring); none for a record made without them (or through the API)."""
    invocation = doc.get("invocation") or {}
    cwd = invocation.get("cwd")
    record_dir = Path(record_path).resolve().parent
    out: list[Finding] = []
    for named in evidence_paths(invocation.get("argv") or []):
        suffix = Path(named).suffix.lower()
        if suffix not in SSP_KINDS:
            continue
        kind = SSP_KINDS[suffix]
        p = Path(named)
        candidates = [p] if p.is_absolute() else [*([Path(cwd) / p] if cwd else [])]
        candidates += [record_dir / p.name, *([Path(inputs) / p.name] if inputs else [])]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            out.append(Finding(kind, p.name, "not here", f"{display_path(named)[:300]}: the "
                               f"{kind.upper()} the run wrote is not here: not compared"))
        elif importlib.util.find_spec("lxml") is None:
            out.append(Finding(kind, p.name, "not checked", "reading it needs lxml: pip "
                               "install 'camera-fidelity[ssp]'", display_path(found)))
        else:
            out.append(check_ssp_file(found, doc))
    return out


__all__ = ["SSP_KINDS", "check_ssp_file", "evidence_paths", "ssp_findings"]
