"""``fidelity check`` and ``fidelity audit`` of 12 and 108 MP JPEGs as whole processes, this
checkout beside an earlier one and beside their anchors, in one interleaved run (issue 59).

The commands, each a fresh process (:func:`tests.fixtures.processes.run_process`: wall time
and the child's own max RSS), ``repeats`` interleaved rounds after one warm-up round (which
also writes the ``.pyc`` files: the processes run compiled, as after ``pip install``), the
odd rounds in reverse order:

- ``python -c "import numpy, cv2"``: the anchor of ``check`` (the interpreter with the two
  libraries any such tool loads);
- ``python -m fidelity check -q --out D`` (its default HTML + JSON report), this checkout and
  ``before``;
- OpenCV's mcc detector as a whole Python process on the 12 MP JPEG (read it, ``process`` with
  one Classic chart): the anchor of the 12 MP audit;
- ``python -m fidelity audit PHOTO -q --json F`` of the 12 MP and the 108 MP JPEG, this
  checkout and ``before``;
- the 12 MP audit of this checkout with its sharpness and noise measurements left out
  (:data:`NO_TEXTURE`: ``noise_and_sharpness`` replaced by one that measures nothing): what
  those measurements add to a whole audit process (issue 55: at most 50 ms);
- ``cv2.imread`` of the 108 MP JPEG as a whole Python process: the decoder, the floor of the
  108 MP audit;
- the 108 MP audit of this checkout once more with the seconds it spent in the uncertainty
  budget (``_window_spread`` and ``image_uncertainty``, timed inside the process as
  tests/measure/test_uncertainty.py does): the budget's share of that process's wall time.

The images are those of :mod:`benchmarks.tools.audit_wall` (the chart render resized to 4000 x
3000 and 12000 x 9000, quality-92 JPEGs). Figures: the median over the rounds.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import run_process, user_environment
from benchmarks.tools.audit_wall import MCC, make_images

REPO = Path(__file__).resolve().parents[2]

ANCHOR = ("python -c 'import numpy, cv2' for check; OpenCV mcc's process as a whole Python "
          "process for the 12 MP audit; cv2.imread as a whole process for the 108 MP audit; "
          "the same command from the earlier checkout (before)")
PARAMETERS = {"repeats": Parameter(5, "interleaved rounds of every command"),
              "before": Parameter(None, "an earlier checkout's source tree (git archive COMMIT "
                                        "| tar -x -C DIR): its commands beside this one's")}
QUICK = {"repeats": 1}

#: The anchor of check.
IMPORTS = "python -c 'import numpy, cv2'"
#: cv2.imread of a file as a whole process.
DECODE = "import sys, cv2\nprint(cv2.imread(sys.argv[1]).shape)\n"
#: ``fidelity`` as a whole process with the chart's sharpness and noise left out of the audit.
NO_TEXTURE = ("import sys\nimport fidelity.measure.pixels as p\n"
              "p.noise_and_sharpness = lambda *a, **k: (None, None)\n"
              "from fidelity.cli import main\nmain(sys.argv[1:], prog_name='fidelity')\n")
#: An audit that writes the seconds it spent in the uncertainty budget to argv[1].
TIMED = (REPO / "tests" / "measure" / "test_uncertainty.py")


def _timed_audit_source() -> str:
    """The ``_TIMED_AUDIT`` harness of tests/measure/test_uncertainty.py (one definition)."""
    text = TIMED.read_text(encoding="utf-8")
    start = text.index('_TIMED_AUDIT = """') + len('_TIMED_AUDIT = """')
    return text[start:text.index('"""', start)]


def _run(argv: list[str], env: dict[str, str], cwd: str) -> tuple[float, float]:
    """Wall seconds and max RSS (MB) of one process, from the folder ``env["_CWD"]`` names
    (the source tree a ``python -m fidelity`` runs), else ``cwd``."""
    env = dict(env)
    row = run_process(argv, env=env, cwd=Path(env.pop("_CWD", cwd)), digits=4)
    if row["exit"] not in (0, 1):
        raise RuntimeError(f"{argv}: exit {row['exit']}: {row['stderr']}")
    return float(row["seconds"]), float(row["max_rss_mb"])


def measure(ctx: Context) -> dict[str, Any]:
    repeats = int(ctx["repeats"])
    before = Path(ctx["before"]).resolve() if ctx["before"] else None
    with tempfile.TemporaryDirectory() as cwd:
        images = make_images(Path(cwd))
        out = Path(cwd)
        py = sys.executable

        def env(tree: Path) -> dict[str, str]:  # run from the tree too (python -m: cwd first)
            return user_environment() | {"PYTHONPATH": str(tree), "_CWD": str(tree)}

        trees = {"this commit": REPO} | ({"before": before} if before else {})
        cmds: dict[str, tuple[list[str], dict[str, str]]] = {
            IMPORTS: ([py, "-c", "import numpy, cv2"], user_environment())}
        for label, tree in trees.items():
            cmds[f"fidelity check ({label})"] = (
                [py, "-m", "fidelity", "check", "-q", "--out", str(out / f"check-{label}")],
                env(tree))
        cmds["OpenCV mcc process, 12 MP"] = ([py, "-c", MCC, str(images["12 MP"])],
                                             user_environment())
        for size in ("12 MP", "108 MP"):
            for label, tree in trees.items():
                cmds[f"fidelity audit {size} ({label})"] = (
                    [py, "-m", "fidelity", "audit", str(images[size]), "-q", "--json",
                     str(out / "a.json")], env(tree))
        cmds[WITHOUT_TEXTURE] = (
            [py, "-c", NO_TEXTURE, "audit", str(images["12 MP"]), "-q", "--json",
             str(out / "n.json")], env(REPO))
        cmds["cv2.imread process, 108 MP"] = ([py, "-c", DECODE, str(images["108 MP"])],
                                              user_environment())
        spent = out / "spent.txt"
        timed = ([py, "-c", _timed_audit_source(), str(spent), "audit",
                  str(images["108 MP"]), "-q", "--json", str(out / "t.json")], env(REPO))
        times: dict[str, list[float]] = {name: [] for name in cmds}
        rss: dict[str, list[float]] = {name: [] for name in cmds}
        shares: list[float] = []
        for argv, e in cmds.values():  # warm-up: the file cache and the .pyc files
            _run(argv, e, cwd)
        for r in range(repeats):
            # odd rounds run the commands in reverse order, so that no command always runs
            # right after the same one (in one order throughout, the 108 MP audit of this
            # checkout, run before the earlier one's, took 1.2x its time; alternating, 0.98x)
            order = list(cmds.items())
            for name, (argv, e) in (order if r % 2 == 0 else order[::-1]):
                t, m = _run(argv, e, cwd)
                times[name].append(t)
                rss[name].append(m)
            t, _ = _run(*timed, cwd)
            shares.append(float(spent.read_text()) / t)
    rows = [{"command": name, "median_s": round(statistics.median(ts), 4),
             "min_s": round(min(ts), 4), "max_rss_mb": round(statistics.median(rss[name]), 1),
             "runs_s": ts} for name, ts in times.items()]
    return {"benchmark": "audit_speed", "repeats": repeats, "rows": rows,
            "before": str(before) if before else None,
            "uncertainty_share_108mp": {"median": round(statistics.median(shares), 4),
                                        "runs": [round(s, 4) for s in shares]},
            "environment": {"PYTHONDONTWRITEBYTECODE": "unset", "cores": os.cpu_count()}}


#: The 12 MP audit of this checkout without its sharpness and noise measurements.
WITHOUT_TEXTURE = "fidelity audit 12 MP without sharpness and noise (this commit)"
#: Most seconds the sharpness and noise measurements may add to the 12 MP audit (issue 55).
TEXTURE_LIMIT_S = 0.050

#: Each command's anchor.
ANCHORS = {"fidelity check (this commit)": IMPORTS, "fidelity check (before)": IMPORTS,
           "fidelity audit 12 MP (this commit)": "OpenCV mcc process, 12 MP",
           "fidelity audit 12 MP (before)": "OpenCV mcc process, 12 MP",
           "fidelity audit 108 MP (this commit)": "cv2.imread process, 108 MP",
           "fidelity audit 108 MP (before)": "cv2.imread process, 108 MP"}
#: Targets of issue 59 (seconds).
TARGETS = {"fidelity check (this commit)": 0.3, "fidelity audit 108 MP (this commit)": 3.0}


def _figures(row: dict[str, Any]) -> Any:
    return figures(row["command"], row["median_s"], best_s=row["min_s"],
                   max_rss_mb=row["max_rss_mb"], runs_s=row.get("runs_s"))


def cases(details: dict[str, Any]) -> list[Case]:
    rows = {r["command"]: r for r in details["rows"]}
    stat = f"median of {details['repeats']} interleaved processes"
    out = [case(name, _figures(r), _figures(rows[ANCHORS[name]]), per="process",
                statistic=stat, process=True, target_s=TARGETS.get(name))
           for name, r in rows.items() if name in ANCHORS]
    for name in rows:  # this commit against the earlier one
        if name.endswith("(this commit)") and name.replace("this commit", "before") in rows:
            other = rows[name.replace("this commit", "before")]
            out.append(case(f"{name[:-len(' (this commit)')]}: this commit / before",
                            _figures(rows[name]), _figures(other), per="process",
                            statistic=stat, process=True))
    if WITHOUT_TEXTURE in rows:
        full, bare = rows["fidelity audit 12 MP (this commit)"], rows[WITHOUT_TEXTURE]
        added = full["median_s"] - bare["median_s"]
        out.append(case("fidelity audit 12 MP: with / without sharpness and noise",
                        _figures(full), _figures(bare), per="process", statistic=stat,
                        process=True,
                        note=f"the measurements add {added * 1000:+.0f} ms (median against "
                             f"median; limit +{TEXTURE_LIMIT_S * 1000:.0f} ms)"))
    share = details["uncertainty_share_108mp"]
    out.append(case("uncertainty budget's share of the 108 MP audit (this commit)",
                    figures("uncertainty share", None), None, per="process",
                    statistic=f"median of {details['repeats']} processes",
                    note=f"share of wall time {share['median']} (runs {share['runs']}); "
                         "limit 0.20"))
    return out
