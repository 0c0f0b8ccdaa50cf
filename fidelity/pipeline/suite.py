"""A suite of camera checks: every camera file of a folder under the illuminant its test case
names, its scene reference adapted to D65 by the case's chromatic adaptation transform.

The suite file is the ``suite.toml`` that ``fidelity validate`` reads
(:func:`fidelity.coco.validate.suite.load_suite`, one reader for one format): camera files
describe the camera, ``suite.toml`` the light each shoots under. :func:`suite_cases` picks the
cases of a command line (the suite file, optionally with some of its camera files);
:func:`run_suite` checks each case (:func:`fidelity.pipeline.check.check_camera` under the
case's illuminant and transform) and returns a :class:`SuiteResult`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fidelity.camera.model import load_camera
from fidelity.coco.validate.suite import CameraCase, is_suite_file, load_suite_file
from fidelity.core.errors import InputFileError
from fidelity.core.record import record
from fidelity.pipeline.check import DEFAULT_CRITERION, check_camera
from fidelity.prediction.judge import DEFAULT_JUDGE, JudgeOptions
from fidelity.prediction.verdict import worst_exit_code

if TYPE_CHECKING:
    from fidelity.coco.measure import MeasureRequest
    from fidelity.pipeline.context import ContextAssessment
    from fidelity.pipeline.records import ChartReport
    from fidelity.prediction.verdict import Criterion


def suite_cases(suite: str, cameras: Sequence[str] = (), default_cat: str | None = None
                ) -> list[CameraCase]:
    """The cases of the suite file ``suite``: all of them, or those of ``cameras`` (camera
    files of the suite's folder, as a shell glob such as ``cameras/*.toml`` gives them), in
    the suite's order. ``default_cat``: the chromatic adaptation transform of the cases the
    suite file gives none of their own (None: the file's ``default_cat``, else Bradford).

    Raises
    ------
    InputFileError
        As :func:`~fidelity.coco.validate.suite.load_suite_file`; a camera that is not a
        camera file of the suite's folder.
    """
    cases = load_suite_file(suite, default_cat)
    if not cameras:
        return cases
    by_path = {c.path.resolve(): c for c in cases}
    for cam in cameras:
        if Path(cam).resolve() not in by_path:
            raise InputFileError(f"{cam}: not a camera file of the suite {suite} (its cases "
                                 f"are the camera files of {Path(suite).parent})")
    wanted = {Path(c).resolve() for c in cameras}
    return [c for c in cases if c.path.resolve() in wanted]


@record
class CaseResult:
    """One case checked: the ``case`` (camera file, illuminant, chromatic adaptation
    transform), its ``report`` and the ``seconds`` it took."""

    case: CameraCase
    report: ChartReport
    seconds: float

    @property
    def exit_code(self) -> int:
        """The report's: 0 pass, 1 fail, 4 undecided."""
        return self.report.exit_code

    def to_json(self) -> dict[str, Any]:
        """The case (with its illuminant and chromatic adaptation transform ``cat``), its ΔE
        and the ΔE's standard uncertainty, predicted ΔmAP, verdict and exit code (the
        summary's row)."""
        r = self.report
        p = r.prediction
        return {"name": self.case.name, "camera_file": str(self.case.path),
                "sha256": self.case.sha256, "illuminant": self.case.illuminant,
                "cat": self.case.cat, "mean_delta_e": float(r.mean_delta_e),
                "delta_e_uncertainty": (float(r.uncertainty.combined)
                                        if r.uncertainty is not None else None), "max_delta_e": float(r.max_delta_e),
                "dmap_points": (float(p.dmap_points) if p is not None
                                and p.dmap_points is not None else None),
                "passed": r.verdict.passed if r.verdict is not None else None,
                "exit_code": self.exit_code, "seconds": self.seconds}


@record
class SuiteResult:
    """Every case of a suite checked (:func:`run_suite`): ``suite`` the suite file, ``cases``
    in order, the ``criterion`` each was judged by and, with a context of use, its
    ``assessment`` (:func:`fidelity.pipeline.context.assess`)."""

    suite: str
    cases: tuple[CaseResult, ...]
    criterion: Criterion | None
    assessment: ContextAssessment | None = None

    @property
    def failed(self) -> tuple[CaseResult, ...]:
        """The cases whose verdict failed."""
        return tuple(c for c in self.cases if c.exit_code == 1)

    @property
    def exit_code(self) -> int:
        """The worst of the cases' (and the assessment's) exit codes."""
        codes = [c.exit_code for c in self.cases]
        if self.assessment is not None:
            codes.append(self.assessment.exit_code)
        return worst_exit_code(codes)

    def to_json(self) -> dict[str, Any]:
        """The summary record: the suite, the criterion, the counts, a row per case and the
        context assessment."""
        crit = self.criterion
        return {"suite": self.suite, "command": "suite",
                "criterion": ({"kind": crit.kind, "limit": crit.limit}
                              if crit is not None else None),
                "cases": len(self.cases), "passed": len(self.cases) - len(self.failed),
                "failed": len(self.failed), "exit_code": self.exit_code,
                "results": [c.to_json() for c in self.cases],
                "context": self.assessment.to_json() if self.assessment else None}


def run_suite(cases: Sequence[CameraCase], *, suite: str = "", renderer: str = "closed-form",
              reference: str = "scene", criterion: Criterion | None = DEFAULT_CRITERION,
              judge: JudgeOptions = DEFAULT_JUDGE,
              measure: MeasureRequest | None = None) -> SuiteResult:
    """Check every case under its own illuminant, its scene reference adapted to D65 by its
    own chromatic adaptation transform.

    Parameters
    ----------
    cases
        The test cases (:func:`suite_cases` or
        :func:`~fidelity.coco.validate.suite.load_suite`).
    suite
        The suite file, for the record.
    renderer, reference, criterion, judge, measure
        As for :func:`fidelity.pipeline.check.check_camera`, the same for every case.

    Returns
    -------
    SuiteResult
        One :class:`CaseResult` per case, in order.

    Raises
    ------
    FidelityError
        As :func:`~fidelity.pipeline.check.check_camera` (exit code 2).
    """
    out = []
    for case in cases:
        t0 = time.perf_counter()
        report = check_camera(load_camera(str(case.path)), illuminant=case.illuminant,
                              cat=case.cat, renderer=renderer, reference=reference, criterion=criterion,
                              judge=judge, measure=measure)
        out.append(CaseResult(case, report, time.perf_counter() - t0))
    return SuiteResult(suite, tuple(out), criterion)


__all__ = ["CaseResult", "SuiteResult", "is_suite_file", "run_suite", "suite_cases"]
