"""Start-up of the command line against the Python interpreter's own (``python -c pass``), and
``fidelity audit`` of a 12-megapixel photo against OpenCV's mcc detector as a whole process.

Each command is run as a fresh process, ``repeats`` times, interleaved (so a busy moment of the
machine hits every command alike), after one warm-up round; the figures are the median wall
time, the fastest run and the median max RSS of the process (each child's own, through
:func:`tests.fixtures.processes.run_process`'s launcher). Targets: ``fidelity --help`` under
0.5 s, ``fidelity predict --delta-e 3`` under 1 s (issue 22); ``fidelity check`` with its default
HTML + JSON report under 1.0 s and ``fidelity audit PHOTO.jpg --json F`` of a 12-megapixel
chart photo under 0.9 s, its anchor OpenCV's mcc detector as a whole Python process on the same
photo (issue 30). The processes run from compiled ``.pyc`` files, as after ``pip install``.
"""

from __future__ import annotations

import shutil
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.speed.record import Case, case, figures
from benchmarks.speed.runner import Context, Parameter
from benchmarks.speed.timing import run_process, user_environment

#: The repository this benchmark runs from.
REPO = Path(__file__).resolve().parents[2]

ANCHOR = ("python -c pass (the interpreter's start-up); OpenCV's mcc detector as a whole "
          "Python process for the audit of the 12 MP photo")
PARAMETERS = {"repeats": Parameter(15, "interleaved rounds of every command"),
              "before": Parameter(None, "a checkout of an earlier commit (git worktree add DIR "
                                        "COMMIT): its start-up beside this one's, both as "
                                        "python -m fidelity from their source trees")}
QUICK = {"repeats": 2}
NEEDS = ("fidelity-command",)

#: A whole Python process that finds the chart with OpenCV's mcc detector (the anchor of the
#: audit): read the photo, detect one Classic chart, print its centre count.
MCC = ("import sys, cv2\n"
       "img = cv2.imread(sys.argv[1])\n"
       "d = cv2.mcc.CCheckerDetector_create()\n"
       "ok = d.process(img, cv2.mcc.MCC24, 1)\n"
       "print(len(d.getListColorChecker()) if ok else 0)\n")
#: The anchor of start-up.
PYTHON = "python -c pass"


#: The commands compared with an earlier commit (``before``), as ``python -m fidelity``.
BEFORE_COMMANDS = {"--help": ["--help"], "check (closed form, no report)": ["check", "--no-report", "-q"]}


def tree_commands(tree: Path, label: str) -> dict[str, tuple[list[str], dict[str, str]]]:
    """:data:`BEFORE_COMMANDS` run from the source tree ``tree`` (``PYTHONPATH``), named
    ``python -m fidelity COMMAND (label)``."""
    env = user_environment() | {"PYTHONPATH": str(tree)}
    return {f"python -m fidelity {name} ({label})": ([sys.executable, "-m", "fidelity", *args], env)
            for name, args in BEFORE_COMMANDS.items()}


def commit_of(tree: Path) -> str:
    """The commit a checkout is at (short id), or its folder's name."""
    import subprocess

    r = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"],
                       capture_output=True, text=True, check=False)
    return r.stdout.strip() or tree.name


def commands(photo: Path, out: Path) -> dict[str, list[str]]:
    """Name -> command line; ``python -c pass`` is the anchor of start-up, the mcc process
    the anchor of the audit."""
    fidelity = shutil.which("fidelity") or "fidelity"
    return {
        PYTHON: [sys.executable, "-c", "pass"],
        "python -c 'import fidelity'": [sys.executable, "-c", "import fidelity"],
        "fidelity --help": [fidelity, "--help"],
        "fidelity predict --delta-e 3": [fidelity, "predict", "--delta-e", "3"],
        "fidelity check (closed form, no report)": [fidelity, "check", "--no-report", "-q"],
        "fidelity check (default HTML + JSON report)": [fidelity, "check", "-q", "--out",
                                                        str(out / "check")],
        "OpenCV mcc on the 12 MP photo (python process)": [sys.executable, "-c", MCC,
                                                           str(photo)],
        "fidelity audit PHOTO.jpg --json F (12 MP)": [fidelity, "audit", str(photo), "-q",
                                                      "--json", str(out / "audit.json")],
    }


#: Targets in seconds (issues 22 and 30).
TARGETS = {"fidelity --help": 0.5, "fidelity predict --delta-e 3": 1.0,
           "fidelity check (default HTML + JSON report)": 1.0,
           "fidelity audit PHOTO.jpg --json F (12 MP)": 0.9}
#: Each row's anchor (the ratio column): the interpreter, or mcc for the audit.
ANCHORS = {"fidelity audit PHOTO.jpg --json F (12 MP)":
           "OpenCV mcc on the 12 MP photo (python process)"}


def run_once(argv: list[str], cwd: str, env: dict[str, str] | None = None
             ) -> tuple[float, float]:
    """Wall seconds and max RSS (MB) of one run of ``argv`` (it must exit 0 or 1)."""
    row = run_process(argv, env=env or user_environment(), cwd=Path(cwd), digits=4)
    if row["exit"] not in (0, 1):
        raise RuntimeError(f"{argv}: exit {row['exit']}: {row['stderr']}")
    return float(row["seconds"]), float(row["max_rss_mb"])


def make_photo(path: Path) -> None:
    """A 4000 x 3000 JPEG: a COCO-like scene with the chart on it
    (:func:`tests.fixtures.photos.photo`)."""
    from tests.fixtures.photos import photo, write_image

    write_image(path, photo(4000, 3000, seed=3))


def measure(ctx: Context) -> dict[str, Any]:
    repeats = ctx["repeats"]
    with tempfile.TemporaryDirectory() as cwd:  # no settings file is found from here
        photo = Path(cwd) / "photo.jpg"
        make_photo(photo)
        cmds: dict[str, tuple[list[str], dict[str, str] | None]] = {
            name: (cmd, None) for name, cmd in commands(photo, Path(cwd)).items()}
        before = ctx["before"]
        anchors = dict(ANCHORS)
        if before:
            label = f"before: {commit_of(Path(before))}"
            ours = tree_commands(REPO, "this commit")
            theirs = tree_commands(Path(before).resolve(), label)
            cmds |= ours | theirs
            anchors |= dict(zip(ours, theirs, strict=True))
        times: dict[str, list[float]] = {name: [] for name in cmds}
        rss: dict[str, list[float]] = {name: [] for name in cmds}
        for cmd, env in cmds.values():  # warm the file cache (and write the .pyc files) once
            run_once(cmd, cwd, env)
        for _ in range(repeats):
            for name, (cmd, env) in cmds.items():
                t, m = run_once(cmd, cwd, env)
                times[name].append(t)
                rss[name].append(m)
    medians = {name: statistics.median(ts) for name, ts in times.items()}
    anchor = medians[PYTHON]
    rows = []
    for name, ts in times.items():
        median = medians[name]
        row: dict[str, object] = {
            "command": name, "median_s": round(median, 4), "min_s": round(min(ts), 4),
            "above_python_s": round(median - anchor, 4),
            "ratio_to_python": round(median / anchor, 2),
            "max_rss_mb": round(statistics.median(rss[name]), 1), "runs_s": ts}
        other = anchors.get(name)
        if other:
            row["anchor"] = other
            row["ratio_to_anchor"] = round(median / medians[other], 2)
        if name in TARGETS:
            row["target_s"] = TARGETS[name]
            row["meets_target"] = median < TARGETS[name]
        rows.append(row)
    return {"benchmark": "startup", "repeats": repeats, "rows": rows,
            "bytecode": "compiled .pyc files (PYTHONDONTWRITEBYTECODE unset), as installed"}


def _figures(row: dict[str, Any]) -> Any:
    return figures(row["command"], row["median_s"], best_s=row["min_s"],
                   max_rss_mb=row["max_rss_mb"], runs_s=row.get("runs_s"))


def cases(details: dict[str, Any]) -> list[Case]:
    rows = {r["command"]: r for r in details["rows"]}
    stat = f"median of {details['repeats']} interleaved processes"
    return [case(name, _figures(r), _figures(rows[r.get("anchor", PYTHON)]), per="process",
                 statistic=stat, process=True, target_s=r.get("target_s"))
            for name, r in rows.items() if name != PYTHON]
