"""Tests for fidelity.pipeline.suite and ``fidelity suite`` / ``check`` with a suite file."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from fidelity.cli import main
from fidelity.core.errors import InputFileError
from fidelity.pipeline.check import check_camera
from fidelity.pipeline.suite import run_suite, suite_cases

CAMERAS = Path(__file__).resolve().parents[2] / "cameras"
NAMES = ["nikon5100-a-daylight-wb", "ideal-srgb8", "nikon5100-f11-awb"]


def make_suite(tmp_path: Path) -> Path:
    d = tmp_path / "cams"
    d.mkdir()
    for n in NAMES:
        shutil.copy(CAMERAS / f"{n}.toml", d / f"{n}.toml")
    (d / "suite.toml").write_text('default_illuminant = "D65"\n[illuminant]\n'
                                  '"nikon5100-a-daylight-wb" = "A"\n"nikon5100-f11-awb" = "F11"\n')
    return d / "suite.toml"


def test_daylight_wb_camera_is_judged_under_a_and_fails(tmp_path: Path) -> None:
    suite = make_suite(tmp_path)
    result = run_suite(suite_cases(str(suite)), suite=str(suite))
    by = {c.case.name: c for c in result.cases}
    a = by["nikon5100-a-daylight-wb"]
    assert a.case.illuminant == "A"
    # the same camera under D65 (what check without the suite did) passes near 1 ΔE
    d65 = check_camera(str(suite.parent / "nikon5100-a-daylight-wb.toml"), illuminant="D65")
    assert d65.mean_delta_e < 3 and d65.verdict is not None and d65.verdict.passed
    # under A it is the independent second run of check_camera under A
    under_a = check_camera(str(suite.parent / "nikon5100-a-daylight-wb.toml"), illuminant="A")
    assert a.report.mean_delta_e == pytest.approx(under_a.mean_delta_e)
    assert a.report.mean_delta_e > 10 * d65.mean_delta_e
    assert a.exit_code == 1 and result.exit_code == 1
    assert by["ideal-srgb8"].exit_code == 0


def test_cli_suite_writes_a_record_per_case_and_a_summary(tmp_path: Path) -> None:
    suite = make_suite(tmp_path)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["suite", str(suite), "--out", str(out)])
    assert r.exit_code == 1, r.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cases"] == 3 and summary["failed"] == 2
    for n in NAMES:
        rep = json.loads((out / n / "report.json").read_text())
        assert (out / n / "report.html").is_file()
        assert rep["source"]["illuminant"] == {"nikon5100-a-daylight-wb": "A",
                                               "nikon5100-f11-awb": "F11"}.get(n, "D65")
    assert "nikon5100-a-daylight-wb/report.html" in (out / "index.html").read_text()


def test_check_glob_with_suite_file_uses_its_illuminants(tmp_path: Path) -> None:
    suite = make_suite(tmp_path)
    args = ["check", *sorted(str(p) for p in suite.parent.iterdir()), "--no-report"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 1, r.output
    line = next(x for x in r.output.splitlines() if "nikon5100-a-daylight-wb" in x)
    assert " A " in line and "FAIL" in line


def test_only_the_passing_case_exits_0(tmp_path: Path) -> None:
    suite = make_suite(tmp_path)
    r = CliRunner().invoke(main, ["check", str(suite), str(suite.parent / "ideal-srgb8.toml"),
                                  "--no-report"])
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("text, key", [
    ('[illuminant]\n"ghost" = "A"\n', "illuminant.ghost"),
    ('[illuminant]\n"ideal-srgb8" = "Q9"\n', "illuminant.ideal-srgb8"),
])
def test_bad_suite_is_one_line_naming_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    suite = make_suite(tmp_path)
    suite.write_text(text)
    with pytest.raises(InputFileError, match=key):
        suite_cases(str(suite))
    r = CliRunner().invoke(main, ["suite", str(suite)])
    assert r.exit_code == 2
    assert str(suite) in r.output and key in r.output


def test_camera_outside_the_suite_is_refused(tmp_path: Path) -> None:
    suite = make_suite(tmp_path)
    with pytest.raises(InputFileError, match="not a camera file of the suite"):
        suite_cases(str(suite), [str(CAMERAS / "sigma-raw-noccm.toml")])


def cat_suite(tmp_path: Path, extra: str) -> Path:
    """The suite of :func:`make_suite` with ``extra`` lines (chromatic adaptation settings)."""
    suite = make_suite(tmp_path)
    suite.write_text(suite.read_text().replace('default_illuminant = "D65"\n',
                                               'default_illuminant = "D65"\n' + extra))
    return suite


def test_a_case_is_checked_with_its_own_chromatic_adaptation(tmp_path: Path) -> None:
    suite = cat_suite(tmp_path, '[cat]\n"nikon5100-f11-awb" = "cat02"\n')
    by = {c.case.name: c for c in run_suite(suite_cases(str(suite)), suite=str(suite)).cases}
    f11 = by["nikon5100-f11-awb"]
    assert f11.case.cat == "CAT02"  # canonical spelling
    assert by["nikon5100-a-daylight-wb"].case.cat == "Bradford"  # no setting: the default
    cam = str(suite.parent / "nikon5100-f11-awb.toml")
    cat02 = check_camera(cam, illuminant="F11", cat="CAT02")
    bradford = check_camera(cam, illuminant="F11", cat="Bradford")
    assert f11.report.mean_delta_e == pytest.approx(cat02.mean_delta_e, rel=1e-12)
    assert abs(cat02.mean_delta_e - bradford.mean_delta_e) > 0.01  # the setting matters
    row = f11.to_json()
    assert row["cat"] == "CAT02"
    assert row["delta_e_uncertainty"] == pytest.approx(cat02.uncertainty.combined)
    names = [c.name for c in f11.report.uncertainty.components]
    assert "chromatic adaptation" in names


def test_default_cat_and_the_command_line_cat(tmp_path: Path) -> None:
    suite = cat_suite(tmp_path, 'default_cat = "Von Kries"\n[cat]\n"nikon5100-f11-awb" = '
                                '"CAT16"\n')
    cats = {c.name: c.cat for c in suite_cases(str(suite))}
    assert cats == {"nikon5100-a-daylight-wb": "Von Kries", "ideal-srgb8": "Von Kries",
                    "nikon5100-f11-awb": "CAT16"}
    # --cat replaces the file's default, never a case's own setting
    cats = {c.name: c.cat for c in suite_cases(str(suite), default_cat="xyz scaling")}
    assert cats["nikon5100-a-daylight-wb"] == "XYZ Scaling"
    assert cats["nikon5100-f11-awb"] == "CAT16"


def test_cli_suite_reports_the_cat_in_table_summary_and_records(tmp_path: Path) -> None:
    suite = cat_suite(tmp_path, '[cat]\n"nikon5100-a-daylight-wb" = "CAT02"\n')
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["suite", str(suite), "--out", str(out), "--cat", "CAT16"])
    assert r.exit_code == 1, r.output
    line = next(x for x in r.output.splitlines() if "nikon5100-a-daylight-wb" in x)
    assert " CAT02 " in line
    line = next(x for x in r.output.splitlines() if "nikon5100-f11-awb" in x)
    assert " CAT16 " in line
    summary = json.loads((out / "summary.json").read_text())
    rows = {x["name"]: x for x in summary["results"]}
    assert rows["nikon5100-a-daylight-wb"]["cat"] == "CAT02"
    assert rows["nikon5100-f11-awb"]["cat"] == "CAT16"
    rep = json.loads((out / "nikon5100-a-daylight-wb" / "report.json").read_text())
    assert rep["provenance"]["conventions"]["render"]["reference"][
        "chromatic_adaptation"] == "CAT02"
    direct = check_camera(str(suite.parent / "nikon5100-a-daylight-wb.toml"),
                          illuminant="A", cat="CAT02")
    assert rows["nikon5100-a-daylight-wb"]["mean_delta_e"] == pytest.approx(
        direct.mean_delta_e, rel=1e-12)
    assert "CAT02" in (out / "index.html").read_text()
    # check of the suite file takes --cat the same way
    r2 = CliRunner().invoke(main, ["check", str(suite), "--cat", "CAT16", "--no-report"])
    assert r2.exit_code == 1, r2.output
    assert " CAT16 " in next(x for x in r2.output.splitlines() if "nikon5100-f11-awb" in x)


@pytest.mark.parametrize("text, key", [
    ('[cat]\n"ideal-srgb8" = "CAT99"\n', "cat.ideal-srgb8"),
    ('default_cat = "nope"\n', "default_cat"),
    ('default_cat = 3\n', "default_cat"),
    ('[cat]\n"ghost" = "CAT02"\n', "cat.ghost"),
])
def test_bad_cat_setting_is_one_line_naming_file_and_key(tmp_path: Path, text: str,
                                                         key: str) -> None:
    suite = make_suite(tmp_path)
    suite.write_text(text)
    with pytest.raises(InputFileError, match=key):
        suite_cases(str(suite))
    r = CliRunner().invoke(main, ["suite", str(suite)])
    assert r.exit_code == 2
    assert r.output.count("\n") == 1 and str(suite) in r.output and key in r.output


def test_docs_context_quotes_the_transforms_delta_e() -> None:
    """docs/context.md: under A, nikon5100-a-awb is 5.38 with Bradford and 5.62 with CAT02."""
    text = (CAMERAS.parent / "docs" / "context.md").read_text()
    cam = str(CAMERAS / "nikon5100-a-awb.toml")
    got = {c: check_camera(cam, illuminant="A", cat=c, criterion=None).mean_delta_e
           for c in ("Bradford", "CAT02")}
    assert (f"`nikon5100-a-awb` is {got['Bradford']:.2f} with\nBradford and "
            f"{got['CAT02']:.2f} with CAT02") in text
