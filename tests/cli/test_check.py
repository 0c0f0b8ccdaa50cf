"""``fidelity check``'s pass rule: ``--max-delta-e`` (default 3, with what it allows) or
``--max-dmap`` with ``--class`` and ``--unit``, as gate's."""

from __future__ import annotations

from click.testing import CliRunner

from fidelity.cli import main
from fidelity.prediction.table import predict


def _check(*args: str):
    return CliRunner().invoke(main, ["check", "--no-report", *args])


def test_max_dmap_relative_fails_the_default_camera_that_delta_e_3_passes():
    by_de = _check()
    assert by_de.exit_code == 0, by_de.output
    assert "(up to 2.39 % of baseline for these detectors)" in by_de.output
    by_loss = _check("--max-dmap", "1", "--unit", "relative")
    assert by_loss.exit_code == 1, by_loss.output
    rel = predict(1.0245).dmap_relative  # about the default camera's ΔE
    assert rel is not None and rel > 1.0
    # colour alone is over the limit; sharpness and noise add to it, with their interaction
    # sqrt(sharpness x noise): sqrt(0.0065 x 0.98) = 0.08 (the edge target's sharpness), and
    # the validated margin: (2.29 + 0.5) exp(0.00577) - 0.5 = 2.31
    assert "FAIL: predicted ΔmAP 2.31 % (colour 1.22 + sharpness 0.01 + noise 0.98 + blur-noise " \
           "interaction 0.08 + validated margin 0.02: colour dominates) > 1" in by_loss.output


def test_max_dmap_of_a_class_in_points():
    r = _check("--max-dmap", "1", "--class", "person")
    assert r.exit_code == 0, r.output
    # the rule's 0.41 with the validated margin of person ΔAP: (0.41 + 0.5) exp(0.0343) - 0.5
    assert "PASS: predicted person ΔAP 0.44 points (colour 0.29 + sharpness 0.00 + noise 0.11 " \
        "+ blur-noise interaction 0.01 + validated margin 0.03" in r.output


def test_the_limits_do_not_go_together():
    assert _check("--max-dmap", "1", "--max-delta-e", "2").exit_code == 2
    assert _check("--class", "person").exit_code == 2
    assert _check("--max-dmap", "1", "--class", "person", "--unit", "relative").exit_code == 2
