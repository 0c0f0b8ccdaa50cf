"""Chart data files: the SAFE-COLOR reference chart and user charts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fidelity.colour.charts import available_charts, load_chart
from fidelity.core.errors import InputFileError, InvalidValueError, UnknownNameError
from fidelity.measure.colour import chart_delta_e, measure_chart


def test_safecolor_chart_matches_the_paper_table() -> None:
    c = load_chart("safecolor")
    assert "safecolor" in available_charts()
    assert (c.rows, c.cols, len(c.patch_names)) == (4, 6, 24)
    assert c.patch_names[0] == "dark skin" and c.patch_names[17] == "cyan" and c.patch_names[23] == "black 2"
    np.testing.assert_array_equal(c.lab[5], [70.72, -33.40, -0.20])  # bluish green
    np.testing.assert_array_equal(c.lab[18], [96.54, -0.48, 1.23])  # white 9.5
    assert c.whitepoint == "D65" and "SAFE-COLOR" in c.provenance
    assert c.neutral_indices == tuple(range(18, 24))
    # Cyan lies outside the sRGB gamut: clipping is what gives the 0.29 baseline.
    assert c.srgb_unclipped[17].min() < 0
    assert 0.28 < chart_delta_e(c.srgb, c.lab) < 0.30


def _write_chart(path: Path, **changes: object) -> Path:
    doc = load_chart().to_json()
    doc.update(changes)
    path.write_text(json.dumps(doc))
    return path


def test_a_user_chart_is_a_file(tmp_path: Path) -> None:
    doc = load_chart().to_json()
    doc["name"] = "two-patch"
    doc["layout"] = {"rows": 1, "cols": 2}
    doc["patches"] = doc["patches"][18:20]
    p = tmp_path / "two.json"
    p.write_text(json.dumps(doc))
    c = load_chart(p)
    assert c.name == "two-patch" and c.patch_names == ("white 9.5", "neutral 8")
    # a file is read once a process while it is unchanged, and again when it changes
    assert load_chart(p) is c and not c.lab.flags.writeable
    doc["patches"] = doc["patches"][::-1]
    p.write_text(json.dumps(doc) + "\n")
    assert load_chart(p).patch_names == ("neutral 8", "white 9.5")


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"patches": []}, "needs 24 patches, found 0"),
        ({"layout": {"rows": 0, "cols": 6}}, "empty"),
        ({"whitepoint": "D50"}, "D65"),
        ({"patches": [{"name": "x", "lab": [1, 2]}] * 24}, "3 finite numbers"),
    ],
)
def test_bad_chart_files_fail_clearly(tmp_path: Path, changes: dict, match: str) -> None:
    p = _write_chart(tmp_path / "bad.json", **changes)
    with pytest.raises(InvalidValueError, match=match):
        load_chart(p)


def test_missing_and_corrupt_chart_files(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="does not exist"):
        load_chart(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputFileError, match="not valid JSON"):
        load_chart(bad)
    with pytest.raises(UnknownNameError, match="safecolor"):
        load_chart("no-such-chart")


def test_measure_chart_reports_per_patch_differences() -> None:
    c = load_chart()
    srgb = c.srgb.copy()
    srgb[0] = np.clip(srgb[0] + 0.1, 0, 1)  # dark skin lighter
    m = measure_chart(srgb, c.lab, c.patch_names)
    assert m.worst_patch == "dark skin" and m.delta_e[0] > 5
    assert m.delta_l[0] > 0
    d = m.to_json()
    assert len(d["patches"]) == 24 and d["patches"][0]["name"] == "dark skin"
    assert d["mean_delta_e"] == pytest.approx(float(np.mean(m.delta_e)))
    with pytest.raises(InvalidValueError, match="patches \\[3\\]"):
        bad = srgb.copy()
        bad[2, 1] = np.nan
        measure_chart(bad, c.lab, c.patch_names)
    with pytest.raises(InvalidValueError, match="shape"):
        measure_chart(srgb[:20], c.lab, c.patch_names)
