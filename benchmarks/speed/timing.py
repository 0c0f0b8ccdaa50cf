"""Timing for the speed benchmarks: best of N calls in process (:func:`best_time`), one whole
process with its wall time, CPU time and own max RSS (:func:`run_process`, from
:mod:`tests.fixtures.processes`), and the environment of the user's processes
(:func:`user_environment`)."""

from __future__ import annotations

import os

from benchmarks.machine import best_time
from tests.fixtures.processes import run_process


def user_environment() -> dict[str, str]:
    """The environment of the runs: this one without ``PYTHONDONTWRITEBYTECODE``, so that the
    modules run from their compiled ``.pyc`` files, as after ``pip install`` (which compiles
    them) or any earlier run; with the variable set, every process compiles fidelity's modules
    from source again (about 0.4 s of each ``check``)."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


__all__ = ["best_time", "run_process", "user_environment"]
