"""Verify a credibility record against the files it names (``fidelity verify RECORD.json``).

What an assessor handed a record (:mod:`fidelity.report.evidence`) asks before relying on it:
are the inputs still the files the record was made from, is the prediction table the one it
names, was the settings file the same, and does the installation at hand run the same code in
the same environment. :func:`verify_record` answers each as a :class:`Finding`:

- every input file, prediction and calibration table, settings file and (for ``fit``) every
  file the run wrote: its SHA-256 now against the recorded one (``unchanged``, ``changed``,
  ``missing``; ``not hashed`` where the record holds no digest);
- the code: this installation's version and code SHA-256 (:func:`~fidelity.report.evidence.
  code_sha256`) against the record's ``tool`` (``same`` or ``differs``);
- the environment: Python and the dependencies' versions against the record's (``same`` or
  ``differs``, naming each version that moved).

With the run repeated (``fidelity verify --rerun``: the recorded command line, its outputs
sent elsewhere), :func:`rerun_finding` compares the new record with the old: the same exit
code, each subject's verdict and error, and each measured value within the record's own
standard uncertainty (``reproduced``); anything else is ``not reproduced``.

A changed or missing file, or a run not reproduced, fails the verification (exit 1): the
record no longer describes those files, or its result. A different code or environment does not: it is reported, since the record stays
a true account of its own run, and says what to install to run it again.

Where a file is looked for: its recorded path (a relative one from the folder the run was
started in, ``invocation.cwd``, then from the record's folder); a file of the package's
shipped data (``.../fidelity/data/...``: built-in cameras, the prediction and calibration
tables) in this installation's data when the recorded path is not there; and, with ``inputs``,
a file of the same name in that folder.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePath
from typing import Any

from fidelity.core import schema as sc
from fidelity.core.fileio import JSONObject, display_path, file_sha256
from fidelity.core.record import record
from fidelity.core.resources import resource_dir, source_root
from fidelity.core.version import __version__
from fidelity.report.evidence import (
    code_sha256,
    environment_record,
    git_commit,
    record_content_sha256,
)
from fidelity.report.recordfiles import record_files

#: Each status a :class:`Finding` can have, and whether it fails the verification.
STATUSES: Mapping[str, bool] = {
    "unchanged": False,   # the file's SHA-256 is the recorded one
    "changed": True,      # the file is there, its SHA-256 is not the recorded one
    "missing": True,      # no file at the recorded path (nor where else it was looked for)
    "not hashed": False,  # the record holds no SHA-256 for it: nothing to compare
    "not here": False,    # a scores file the table names, not in this installation (a wheel)
    "intact": False,      # the record's content hash is that of its content
    "edited": True,       # the record's content hash is not that of its content (or absent)
    "same": False,        # code, version or environment as recorded
    "differs": False,     # code or environment not as recorded (reported, not failed)
    "other version": False,  # made by another fidelity version (reported, not failed)
    "inconsistent": True,  # the recorded code hash is this installation's, the version not
    "reproduced": False,  # run again: the same exit code, verdicts, and values within u
    "not reproduced": True,
    "linked": False,      # --chain: this link holds (hash as recorded, rows as rebuilt)
    "broken": True,       # --chain: this link does not hold
    "not rebuilt": False,  # --chain: a table that names no scores files (published bounds)
    "not checked": False,  # an SRMD or STMD here, but lxml (the ssp extra) is not installed
}

#: The kinds of :class:`Finding` that are not a file the record names.
NOT_FILES = ("content", "version", "code", "environment", "rerun", "chain", "srmd", "stmd")

#: The layout versions of the credibility record this version reads.
READABLE_VERSIONS = ("1.0", "1.1", "1.2")

#: The first layout that holds ``record.content_sha256`` (and requires it).
HASHED_FROM = "1.2"

_HEX64 = re.compile(r"[0-9a-f]{64}")


def _sha256_field(table: Mapping[str, Any]) -> tuple[str, str] | None:
    value = table.get("sha256")
    if value is not None and not _HEX64.fullmatch(value):
        return "sha256", f"must be 64 lower-case hexadecimal digits, got {value!r:.80}"
    return None


def _content_field(table: Mapping[str, Any]) -> tuple[str, str] | None:
    value = table.get("content_sha256")
    if value is not None and not _HEX64.fullmatch(value):
        return "content_sha256", f"must be 64 lower-case hexadecimal digits, got {value!r:.80}"
    return None


_FILE = sc.Table(fields=(
    sc.Field("path", sc.String(nullable=True), required=True),
    sc.Field("sha256", sc.String(nullable=True)),
), extra=True, rules=(sc.Check(_sha256_field),), nullable=True)

_INPUT = sc.Table(fields=(
    sc.Field("role", sc.String(), required=True),
    sc.Field("path", sc.String(nullable=True), required=True),
    sc.Field("sha256", sc.String(nullable=True)),
), extra=True, rules=(sc.Check(_sha256_field),))

_TABLE = sc.Table(fields=(
    sc.Field("name", sc.String(), required=True),
    sc.Field("path", sc.String(nullable=True)),
    sc.Field("sha256", sc.String(nullable=True)),
    sc.Field("calibration", sc.Table(fields=(
        sc.Field("name", sc.String(nullable=True)),
        sc.Field("path", sc.String(nullable=True)),
        sc.Field("sha256", sc.String(nullable=True)),
    ), extra=True, rules=(sc.Check(_sha256_field),), nullable=True)),
), extra=True, rules=(sc.Check(_sha256_field),), nullable=True)

#: The parts of the credibility record (``evidence.schema.json``) that verifying reads.
RECORD_SCHEMA = sc.Table(fields=(
    sc.Field("record", sc.Table(fields=(
        sc.Field("schema", sc.String(choices=("fidelity credibility record",),
                                     ignore_case=False), required=True),
        sc.Field("schema_version", sc.String(choices=READABLE_VERSIONS, ignore_case=False),
                 required=True),
        sc.Field("created", sc.String(), required=True),
        sc.Field("command", sc.String(), required=True),
        sc.Field("exit_code", sc.Integer(lo=0), required=True),
        sc.Field("outcome", sc.String(), required=True),
        sc.Field("content_sha256", sc.String(nullable=True)),
    ), extra=True, rules=(sc.Check(_content_field),)), required=True),
    sc.Field("tool", sc.Table(fields=(
        sc.Field("version", sc.String(), required=True),
        sc.Field("commit", sc.String(nullable=True)),
        sc.Field("dirty", sc.Boolean(nullable=True)),
        sc.Field("code_sha256", sc.String(nullable=True)),
    ), extra=True), required=True),
    sc.Field("environment", sc.Table(fields=(
        sc.Field("python", sc.String(), required=True),
        sc.Field("dependencies", sc.MapOf(sc.String(nullable=True)), default={}),
    ), extra=True), required=True),
    sc.Field("invocation", sc.Table(fields=(
        sc.Field("argv", sc.ListOf(sc.String()), required=True),
        sc.Field("cwd", sc.String(nullable=True)),
        sc.Field("settings", _FILE),
    ), extra=True, nullable=True)),
    sc.Field("subjects", sc.ListOf(sc.Table(fields=(
        sc.Field("subject", sc.String(), required=True),
        sc.Field("inputs", sc.ListOf(_INPUT), required=True),
        sc.Field("prediction_table", _TABLE),
        sc.Field("correction", sc.Table(fields=(
            sc.Field("files", sc.MapOf(_FILE), default={}),
        ), extra=True, nullable=True)),
    ), extra=True)), required=True),
), extra=True)

#: The largest record read (a record of a gate over many images is a few MiB at most).
MAX_RECORD_BYTES = 64 * 2**20


@record
class Finding:
    """One comparison of the record with what is here.

    ``kind``: ``input``, ``prediction table``, ``calibration table``, ``settings``, ``output``
    (a file the run wrote), ``code`` or ``environment``; ``name``: which (an input's role, a
    table's name); ``status``: one of :data:`STATUSES`; ``detail``: what was compared;
    ``path``: the file compared (None for code and environment, or when none was found)."""

    kind: str
    name: str
    status: str
    detail: str
    path: str | None = None

    @property
    def failed(self) -> bool:
        return STATUSES[self.status]

    def to_json(self) -> JSONObject:
        return {"kind": self.kind, "name": self.name, "status": self.status,
                "failed": self.failed, "detail": self.detail, "path": self.path}


@record
class Verification:
    """The outcome of :func:`verify_record`: the record's ``path``, what the record says of its
    run (``command``, ``created``, ``exit_code``, ``outcome``, the tool's ``version`` and
    ``commit``) and the ``findings``, in the order checked."""

    path: str
    command: str
    created: str
    exit_code: int
    outcome: str
    version: str
    commit: str | None
    findings: tuple[Finding, ...]

    @property
    def verified(self) -> bool:
        """No file the record names has changed or gone missing."""
        return not any(f.failed for f in self.findings)

    def count(self, status: str, among: Sequence[Finding] | None = None) -> int:
        return sum(f.status == status for f in (self.findings if among is None else among))

    def to_json(self) -> JSONObject:
        return {"record": self.path, "command": self.command, "created": self.created,
                "exit_code": self.exit_code, "outcome": self.outcome,
                "tool": {"version": self.version, "commit": self.commit},
                "verified": self.verified,
                "counts": {s: self.count(s) for s in STATUSES if self.count(s)},
                "findings": [f.to_json() for f in self.findings]}


def read_record(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The credibility record at ``path`` (JSON), the parts verifying reads validated
    (:data:`RECORD_SCHEMA`); raises :class:`~fidelity.core.schema.SchemaError` naming the file and
    the field."""
    where = display_path(path)
    if Path(path).suffix.lower() != ".json":
        raise sc.SchemaError(f"{where}: fidelity verify reads the JSON credibility record "
                             "(--evidence FILE.json); the SSP and ASAM QC files carry their "
                             "own checksums for their own tools")
    doc = sc.load_document(path, max_bytes=MAX_RECORD_BYTES, what="record")
    if isinstance(doc, dict) and isinstance(doc.get("record"), dict):
        version = doc["record"].get("schema_version")
        if isinstance(version, str) and version not in READABLE_VERSIONS and \
                doc["record"].get("schema") == "fidelity credibility record":
            raise sc.SchemaError(f"{where}: record.schema_version: {version!r} is newer than "
                                 f"this fidelity reads ({', '.join(READABLE_VERSIONS)}); "
                                 "verify it with the version that wrote it")
    validated: dict[str, Any] = sc.validate(doc, RECORD_SCHEMA, where)
    return validated


def _is_file(path: Path) -> bool:
    """``path`` is a regular file here (a name too long for the system, or holding a NUL, is
    not one)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _shipped_copy(recorded: str) -> Path | None:
    """This installation's copy of a file of the package's shipped data named by another
    installation's path (``.../fidelity/data/<rest>``), if it has one."""
    parts = PurePath(recorded).parts
    for i in range(len(parts) - 2, -1, -1):
        if parts[i] == "fidelity" and parts[i + 1] == "data":
            candidate = resource_dir("data").joinpath(*parts[i + 2:])
            return candidate if _is_file(candidate) else None
    return None


def locate(recorded: str, cwd: str | None, record_dir: Path,
           inputs: Path | None = None) -> Path | None:
    """Where the file recorded as ``recorded`` is here (module docstring), or None."""
    p = Path(recorded)
    candidates = [p] if p.is_absolute() else [
        *([Path(cwd) / p] if cwd else []), record_dir / p, p]
    if not p.is_absolute():  # a file of the source checkout (reports/coco/...)
        candidates.append(source_root() / p)
    for c in candidates:
        if _is_file(c):
            return c
    shipped = _shipped_copy(recorded)
    if shipped is not None:
        return shipped
    if inputs is not None and p.name and _is_file(inputs / p.name):
        return inputs / p.name
    return None


def _file_finding(kind: str, name: str, recorded: str | None, sha256: str | None,
                  cwd: str | None, record_dir: Path, inputs: Path | None) -> Finding:
    if recorded is None:
        return Finding(kind, name, "not hashed", "the record names no file", None)
    found = locate(recorded, cwd, record_dir, inputs)
    if found is None:
        if kind == "scores file":  # evidence behind the table, shipped in the source only
            return Finding(kind, name, "not here", f"{display_path(recorded)[:300]} is not in "
                           "this installation (the source checkout has it): not compared",
                           None)
        return Finding(kind, name, "missing", f"{display_path(recorded)[:300]} is not there "
                       "(no such file)", None)
    shown = display_path(found)
    if sha256 is None:
        return Finding(kind, name, "not hashed", "the record holds no SHA-256 for it", shown)
    try:
        now = file_sha256(found)
    except OSError as exc:
        return Finding(kind, name, "missing", f"cannot be read: {exc.strerror or exc}", shown)
    if now == sha256:
        return Finding(kind, name, "unchanged", f"SHA-256 {sha256[:12]}", shown)
    return Finding(kind, name, "changed", f"SHA-256 {now[:12]}, recorded {sha256[:12]}", shown)


def _code_finding(tool: Mapping[str, Any]) -> Finding:
    def named(version: str, commit: str | None, dirty: bool | None) -> str:
        return f"fidelity {version}" + (
            f" ({commit[:7]}{' with uncommitted changes' if dirty else ''})" if commit else "")

    here = code_sha256()
    recorded = tool.get("code_sha256")
    where = named(tool["version"], tool.get("commit"), tool.get("dirty"))
    if recorded == here and tool["version"] != __version__:
        # the version is in the code (fidelity/core/version.py): one without the other is an
        # edit
        return Finding("code", "fidelity", "inconsistent",
                       f"the recorded code SHA-256 {here[:12]} is this installation's, which "
                       f"is fidelity {__version__}, but the record names fidelity "
                       f"{tool['version']}: the record was edited")
    if recorded == here:
        return Finding("code", "fidelity", "same", f"{where}: code SHA-256 {here[:12]}")
    now = named(__version__, *git_commit())
    was = f"code SHA-256 {recorded[:12]}" if recorded else "no code SHA-256 recorded"
    return Finding("code", "fidelity", "differs",
                   f"recorded {where}, {was}; here {now}, code SHA-256 {here[:12]}")


def _version_finding(tool: Mapping[str, Any]) -> Finding:
    """The recorded fidelity version against the installed one: ``same``, or ``other
    version`` (reported, not failed: verify the files with any version; repeat the run
    exactly with the recorded one)."""
    if tool["version"] == __version__:
        return Finding("version", "fidelity", "same", f"fidelity {__version__}, as installed")
    return Finding("version", "fidelity", "other version",
                   f"made by fidelity {tool['version']}, verified with fidelity {__version__}: "
                   f"install fidelity {tool['version']} to repeat the run exactly")


def content_finding(doc: Mapping[str, Any]) -> Finding:
    """The record's hash of its own content (``record.content_sha256``, layout 1.2) against
    the hash of its content now (:func:`~fidelity.report.evidence.record_content_sha256`):
    ``intact``, or ``edited`` (a field changed, or the hash removed, after it was written);
    ``not hashed`` for a record of layout 1.0 or 1.1, which holds none."""
    rec = doc["record"]
    recorded = rec.get("content_sha256")
    version = rec["schema_version"]
    if recorded is None:
        if READABLE_VERSIONS.index(version) < READABLE_VERSIONS.index(HASHED_FROM):
            return Finding("content", "record", "not hashed",
                           f"a record of layout {version} holds no content hash")
        return Finding("content", "record", "edited",
                       f"the record's content hash is missing, which layout {version} "
                       "requires: the record was edited")
    now = record_content_sha256(doc)
    if now == recorded:
        return Finding("content", "record", "intact", f"content SHA-256 {now[:12]}")
    return Finding("content", "record", "edited",
                   "the record's content hash does not match: the record was edited (content "
                   f"SHA-256 {now[:12]}, recorded {recorded[:12]})")


def _environment_finding(env: Mapping[str, Any]) -> Finding:
    here = environment_record()
    moved = []
    if env["python"] != here["python"]:
        moved.append(f"Python {env['python']} -> {here['python']}")
    deps_here = here["dependencies"]
    for name in sorted(set(env["dependencies"]) | set(deps_here), key=str.lower):
        was, now = env["dependencies"].get(name), deps_here.get(name)
        if was != now:
            moved.append(f"{name} {was or 'absent'} -> {now or 'absent'}")
    n = len(env["dependencies"])
    if not moved:
        return Finding("environment", "Python and libraries", "same",
                       f"Python {here['python']} and {n} libraries' versions as recorded")
    return Finding("environment", "Python and libraries", "differs", "; ".join(moved))


def verify_record(path: str | os.PathLike[str], *, inputs: str | os.PathLike[str] | None = None
                  ) -> Verification:
    """Verify the credibility record at ``path`` (module docstring); ``inputs``: a folder in
    which to look for files not found where the record says (by file name)."""
    return verify_document(read_record(path), path, inputs=inputs)


def verify_document(doc: Mapping[str, Any], path: str | os.PathLike[str], *,
                    inputs: str | os.PathLike[str] | None = None) -> Verification:
    """:func:`verify_record` of a record already read (:func:`read_record`) from ``path``."""
    record_dir = Path(path).resolve().parent
    where = Path(inputs) if inputs is not None else None
    invocation = doc.get("invocation") or {}
    cwd = invocation.get("cwd")
    findings: list[Finding] = [content_finding(doc)]
    seen: set[tuple[str, str | None, str | None]] = set()

    def add(kind: str, name: str, file: Mapping[str, Any] | None) -> None:
        if not file:
            return
        key = (kind, file.get("path"), file.get("sha256"))
        if key in seen:  # a file several subjects name (a gate's table) once
            return
        seen.add(key)
        findings.append(_file_finding(kind, name, file.get("path"), file.get("sha256"), cwd,
                                      record_dir, where))

    for kind, name, file in record_files(doc, evidence=True):
        add(kind, name, file)
    findings.append(_version_finding(doc["tool"]))
    findings.append(_code_finding(doc["tool"]))
    findings.append(_environment_finding(doc["environment"]))
    rec = doc["record"]
    return Verification(display_path(path), rec["command"], rec["created"], rec["exit_code"],
                        rec["outcome"], doc["tool"]["version"], doc["tool"].get("commit"),
                        tuple(findings))


def _subject_outcome(subject: Mapping[str, Any]) -> tuple[Any, Any, Any, Any, str]:
    """A subject's measured value, its standard uncertainty, verdict label, error and the
    name of the quantity measured."""
    m = subject.get("measurement") or {}
    u = (m.get("uncertainty") or {}).get("standard_uncertainty")
    return (m.get("value"), u, (subject.get("verdict") or {}).get("label"),
            subject.get("error"), str(m.get("quantity") or "value"))


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def rerun_finding(recorded: Mapping[str, Any], rerun: Mapping[str, Any] | None,
                  exit_code: int, message: str = "") -> Finding:
    """The run repeated, compared with its record: ``recorded`` and ``rerun`` are the two
    records (``rerun`` None when the repeat wrote none), ``exit_code`` the repeat's and
    ``message`` its last line of errors. Reproduced: the recorded exit code, and per subject
    (in order) the same verdict label and error and a value within the recorded standard
    uncertainty ``u`` (within 1e-9 of it, relative, where ``u`` is zero or not recorded),
    and each file a fit wrote (the ``.cube``, its OCIO config) with the recorded bytes."""
    want = recorded["record"]["exit_code"]
    if rerun is None:
        why = f": {message}" if message else ""
        return Finding("rerun", recorded["record"]["command"], "not reproduced",
                       f"the run ended with exit {exit_code} and wrote no record{why}")
    problems: list[str] = []
    notes: list[str] = []
    if exit_code != want:
        problems.append(f"exit {exit_code}, recorded {want}")
    old, new = list(recorded["subjects"]), list(rerun.get("subjects") or [])
    if [s.get("subject") for s in old] != [s.get("subject") for s in new]:
        problems.append(f"{len(new)} subjects, recorded {len(old)}")
    for a, b in zip(old, new, strict=False):
        name = a.get("subject")
        va, ua, la, ea, quantity = _subject_outcome(a)
        vb, _, lb, eb, _ = _subject_outcome(b)
        if la != lb:
            problems.append(f"{name}: {lb or 'no verdict'}, recorded {la or 'no verdict'}")
        if (ea is None) != (eb is None):
            problems.append(f"{name}: {'error: ' + str(eb) if eb else 'no error'}, recorded "
                            f"{'error: ' + str(ea) if ea else 'no error'}")
        if _number(va) and _number(vb):
            diff = float(vb) - float(va)
            u = float(ua) if _number(ua) else 0.0
            within = abs(diff) <= (u if u > 0 else 1e-9 * max(1.0, abs(float(va))))
            how = ("identical" if diff == 0 else
                   f"{float(vb):.6g}, recorded {float(va):.6g}"
                   + (f" ({abs(diff) / u:.2f} u)" if u > 0 else ""))
            (notes if within else problems).append(f"{name}: {quantity} {how}")
        elif _number(va) != _number(vb):
            problems.append(f"{name}: {quantity} {vb}, recorded {va}")
        written_a = (a.get("correction") or {}).get("files") or {}
        written_b = (b.get("correction") or {}).get("files") or {}
        for key in sorted(set(written_a) & set(written_b)):
            same = (written_a[key] or {}).get("sha256") == (written_b[key] or {}).get("sha256")
            (notes if same else problems).append(
                f"{name}: {key} {'the same bytes' if same else 'other bytes than recorded'}")
    if problems:
        return Finding("rerun", recorded["record"]["command"], "not reproduced",
                       "; ".join(problems + notes))
    return Finding("rerun", recorded["record"]["command"], "reproduced",
                   f"exit {exit_code} as recorded; " + "; ".join(notes or ["no values"]))


def verification_lines(v: Verification) -> list[str]:
    """The terminal lines of ``fidelity verify``."""
    commit = f" ({v.commit[:7]})" if v.commit else ""
    out = [f"fidelity verify: {v.path}: {v.command} of {v.created}, fidelity {v.version}"
           f"{commit}, exit {v.exit_code} ({v.outcome})"]
    for f in v.findings:
        label = f.kind if f.kind in NOT_FILES and f.kind != "chain" else f"{f.kind} {f.name}"
        at = f" {f.path}" if f.path else ""
        out.append(f"  {label}{at}: {f.status}; {f.detail}")
    files = [f for f in v.findings if f.kind not in NOT_FILES]
    bad = [f"{v.count(s, files)} {s}" for s in ("changed", "missing") if v.count(s, files)]
    unhashed = v.count("not hashed", files)
    summary = (f"{', '.join(bad)} of {len(files)} files" if bad else
               f"{v.count('unchanged')} of {len(files)} files unchanged")
    if unhashed:
        summary += f" ({unhashed} without a recorded SHA-256)"
    if v.count("not here"):
        summary += f" ({v.count('not here')} not in this installation)"
    summary += "".join(f", record {f.status}" for f in v.findings if f.kind == "content")
    summary += "".join(f", {f.kind.upper()} {f.status}" for f in v.findings
                       if f.kind in ("srmd", "stmd"))
    summary += "".join(f", version {f.status}" for f in v.findings
                       if f.kind == "version" and f.status != "same")
    summary += "".join(f", code {f.status}" for f in v.findings
                       if f.kind == "code" and f.status == "inconsistent")
    summary += "".join(f", run again: {f.status}" for f in v.findings if f.kind == "rerun")
    links = [f for f in v.findings if f.kind == "chain"]
    broken = [f.name for f in links if f.status == "broken"]
    if broken:
        summary += f", chain broken at {'; '.join(broken)}"
    elif links:
        summary += f", chain: {v.count('linked', links)} links hold"
    out.append(f"{'VERIFIED' if v.verified else 'NOT VERIFIED'}: {summary}")
    return out


__all__ = ["MAX_RECORD_BYTES", "READABLE_VERSIONS", "RECORD_SCHEMA", "STATUSES", "Finding",
           "Verification", "locate", "read_record", "rerun_finding", "verification_lines",
           "verify_document", "verify_record"]
