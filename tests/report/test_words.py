"""Predictions and verdicts in words (fidelity.report.words): each sentence carries the fields'
numbers, and one sentence per reason. The wording itself is pinned by the JSON outputs
(tests/cli/test_json_outputs.py); here the numbers and the choice of sentence."""

from __future__ import annotations

import dataclasses

import pytest

from fidelity import check_camera
from fidelity.prediction import interpolate as ip
from fidelity.prediction import table as pr
from fidelity.prediction import tablefile as tf
from fidelity.prediction.verdict import Criterion, VerdictReason, evaluate, judge_value
from fidelity.report.words import (
    ceiling_words,
    column_note,
    prediction_notes,
    property_lines,
    verdict_message,
)
from tests.prediction.test_table import SC, _measured_table


def test_the_sampling_error_note_gives_the_two_bracketing_ses() -> None:
    doc = _measured_table()
    for curve, ses in zip(doc["curves"][:2], ([0.1, 0.3, 0.2, 0.5], [0.15, 0.25, 0.4, 0.6]),
                          strict=True):
        for point, se in zip(curve["points"], ses, strict=True):
            point["dmap_points_se"] = se
    p = pr.predict(4.0, size="n", table=tf.parse_prediction_table(doc), transforms=False)
    notes = prediction_notes(p)
    assert sum("0.25-0.40" in n for n in notes) == 1
    p3 = pr.predict(3.0, size="n", table=tf.parse_prediction_table(doc), transforms=False)
    assert sum(" 0.25 points" in n for n in prediction_notes(p3)) == 1
    plain = pr.predict(3.0, size="n", table=tf.parse_prediction_table(_measured_table()),
                       transforms=False)
    assert len(prediction_notes(plain)) == len(notes) - 1  # no SE: no SE sentence


def test_a_raised_relative_loss_names_points_baseline_and_result() -> None:
    p = pr.predict(6.0, table=SC, baseline_map=37.5, transforms=False)
    note = column_note(p, "dmap_relative")
    assert "100*3/37.5 = 8 %" in note
    plain = pr.predict(6.0, table=SC, transforms=False)
    assert "100*" not in column_note(plain, "dmap_relative")
    # the published-bounds notes: one more sentence without the baseline (the ambiguity)
    assert len(prediction_notes(plain)) == len(prediction_notes(p)) + 1


def test_ceilings_in_words_carry_the_baseline() -> None:
    assert ceiling_words("dmap_points", 38.0).startswith("38 points")
    assert ceiling_words("dap_person_points", 100.0).startswith("100 points")
    assert ceiling_words("dap_person_points", None).startswith("100 points")
    assert ceiling_words("dmap_relative", 100.0) == "100 %"


def test_every_size_fallback_says_which_sizes_answered() -> None:
    table = tf.parse_prediction_table(_measured_table())
    m = pr.predict(5.0, size="m", table=table, transforms=False)
    assert sum("'m'" in n and "sizes n, x" in n for n in prediction_notes(m)) == 1
    n = pr.predict(5.0, size="n", table=table, transforms=False)
    assert not any("'n'" in s for s in prediction_notes(n))


@pytest.mark.parametrize(("value", "reason", "head"), [
    (0.5, VerdictReason.WITHIN_LIMIT, "PASS"),
    (1.5, VerdictReason.OVER_LIMIT, "FAIL"),
    (None, VerdictReason.NO_PREDICTION, "FAIL"),
])
def test_a_verdict_message_per_reason(value, reason, head) -> None:
    v = judge_value(Criterion("max-dmap", 1.0), value, 2.41, table="t")
    assert v.reason is reason and v.passed == (head == "PASS")
    message = verdict_message(v)
    assert message.startswith(head + ":")
    if value is None:
        assert "'t'" in message and v.conservative
    else:
        assert f"{value:.2f} points" in message and "2.41" in message


def test_the_verdict_on_the_chart_delta_e_and_the_comparisons_name_for_it() -> None:
    v = evaluate(3.2, None, Criterion("max-delta-e", 3.0))
    assert v.reason is VerdictReason.OVER_LIMIT and v.value == v.delta_e == 3.2
    assert verdict_message(v).startswith("FAIL: mean ΔE00 3.20 > 3")
    assert verdict_message(v, "sim-to-real ΔE00").startswith("FAIL: sim-to-real ΔE00 3.20")


def test_a_conservative_answer_says_its_status() -> None:
    p = pr.predict(30.0, table=SC, transforms=False)
    v = evaluate(30.0, p, Criterion("max-dmap", 200.0))
    assert v.passed and v.conservative and v.status is ip.ColumnStatus.ABOVE_RANGE
    assert v.upper_bound and "above-range" in verdict_message(v)


def test_a_zero_baseline_measured_loss_renders_as_undefined() -> None:
    """A detector with baseline mAP 0 has no relative loss (fidelity.coco.loss): the report
    says so instead of failing on None."""
    from fidelity.coco.measure import MeasuredLoss
    from fidelity.pipeline.check import check_camera
    from fidelity.report.chart import measured_section
    from fidelity.report.document import Table

    loss = MeasuredLoss("m", "m.onnx", "0" * 64, "k", 10, 0.0, 0.0, 0.0, None, None, None,
                        None, None, None, None, 1.0, 10, False, "coco", {})
    report = dataclasses.replace(check_camera("ideal"), measured=(loss,))
    section = measured_section(report)
    assert section is not None
    rows = [b for b in section.blocks if isinstance(b, Table)][0].rows
    assert rows[0][4] == "– ± –" and rows[0][3] == "0.00 ± –"


def _signed_fixed_formats_without_z(source: str) -> list[str]:
    """The format specs in ``source``'s f-strings that print a sign and a fixed-point number
    (``+.2f``) but do not turn a negative zero into zero (``+z.2f``)."""
    import ast
    import re

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FormattedValue) and isinstance(node.format_spec, ast.JoinedStr):
            spec = "".join(v.value for v in node.format_spec.values
                           if isinstance(v, ast.Constant) and isinstance(v.value, str))
            if re.fullmatch(r"[<>=^]?\+\d*\.\d+f", spec):
                found.append(spec)
    return found


def test_no_signed_number_prints_as_minus_zero() -> None:
    """Every signed fixed-point number the package prints (exposure in EV, ΔL*, matrix entries)
    uses the ``z`` option: -0.001 EV reads "+0.00 EV", never "-0.00 EV"."""
    from pathlib import Path

    assert f"{-0.001:+z.2f}" == "+0.00" and f"{-0.001:+.2f}" == "-0.00"
    assert _signed_fixed_formats_without_z('f"{x:+.2f} {y:+z.1f}"') == ["+.2f"]
    package = Path(__file__).resolve().parents[2] / "fidelity"
    offenders = {str(p.relative_to(package)): found for p in sorted(package.rglob("*.py"))
                 if (found := _signed_fixed_formats_without_z(p.read_text(encoding="utf-8")))}
    assert offenders == {}


def test_the_combined_loss_is_a_line_with_its_uncertainty_rule_and_dominant() -> None:
    """The default check's property lines end with the combined loss (its value and ± u as
    the judgement holds them, the rule, the parts and the dominant property), before the
    limits."""
    j = check_camera("nikon-5100").properties
    assert j is not None and j.combined is not None and j.combined.u_loss is not None
    lines = property_lines(j)
    c = j.combined
    assert c.margin > 0
    assert lines[-2] == (f"combined: predicted ΔmAP {c.loss:.2f} ± {c.u_loss:.2f} points "
                         f"({c.rule} of colour, sharpness, noise, + {c.margin:.2f} validated "
                         f"margin; {c.dominant} dominates)")
    assert lines[-1].startswith("limits equivalent to ΔE00 3")
    parts = c.parts
    assert c.loss == pytest.approx(sum(parts.values()) + c.interaction + c.margin)
