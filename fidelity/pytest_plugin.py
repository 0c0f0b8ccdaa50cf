"""A pytest plugin: assert a simulator's rendered images keep their colour.

Installed with camera-fidelity (entry point ``pytest11``), it gives every test suite the
``colour_fidelity`` fixture::

    import pytest

    def test_day_render_keeps_colour(colour_fidelity):
        assert colour_fidelity("renders/day.exr") <= 3      # mean ΔE00 of the chart

The fixture measures the chart in an image (found, or given by ``corners=``) with
:func:`fidelity.audit_image` and returns a :class:`ColourFidelity`: a float (the mean ΔE00) that
also carries the whole :class:`~fidelity.pipeline.records.ChartReport` (``.report``). The measured
values are recorded as JUnit properties, so a CI shows them: properties of the test case under
``junit_family`` ``legacy`` or ``xunit1``, and under ``xunit2`` (pytest's default, whose schema
allows properties only on the suite) properties of the test suite named after the test
(``TEST_ID:IMAGE:mean_delta_e``), without pytest's warning about ``record_property``.

A marker sets the fixture's defaults for one test::

    @pytest.mark.colour_fidelity(reference="safecolor", illuminant="D50")
    def test_studio_photo(colour_fidelity): ...
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import fields
from typing import TYPE_CHECKING, Any

import pytest

from fidelity.chart.read import ReadOptions
from fidelity.pipeline.check import audit_image
from fidelity.prediction.judge import JudgeOptions

if TYPE_CHECKING:
    from fidelity.pipeline.records import ChartReport


class ColourFidelity(float):
    """The chart's mean ΔE00 of an image (compare it with a limit), with its ``report``."""

    report: ChartReport

    def __new__(cls, report: ChartReport) -> ColourFidelity:
        value = super().__new__(cls, report.mean_delta_e)
        value.report = report
        return value

    def __repr__(self) -> str:
        return (f"ColourFidelity(mean ΔE00 {float(self):.3f}, max "
                f"{self.report.max_delta_e:.3f} ({self.report.worst_patch}))")


def pytest_configure(config: pytest.Config) -> None:
    """Declare the ``colour_fidelity`` marker."""
    config.addinivalue_line(
        "markers", "colour_fidelity(**options): defaults of the colour_fidelity fixture "
                   "(reference, illuminant, corners, ...; see fidelity.audit_image)")


def _recorder(request: pytest.FixtureRequest) -> Callable[[str, object], None]:
    """Where a measured value goes: the test's own properties (``user_properties``: JUnit
    ``legacy``/``xunit1``, or no JUnit file), else, under ``xunit2`` with ``--junitxml``, the
    suite's properties prefixed with the test's id."""
    xml_path = getattr(request.config.option, "xmlpath", None)
    family = str(request.config.getini("junit_family") or "xunit2")
    if not xml_path or family in ("legacy", "xunit1"):
        props = request.node.user_properties
        return lambda name, value: props.append((name, value))
    record_suite: Callable[[str, object], None] = request.getfixturevalue(
        "record_testsuite_property")
    test_id = request.node.nodeid
    return lambda name, value: record_suite(f"{test_id}:{name}", value)


@pytest.fixture
def colour_fidelity(request: pytest.FixtureRequest) -> Callable[..., ColourFidelity]:
    """Measure the chart in an image: ``colour_fidelity(path, **options)`` -> mean ΔE00."""
    record_property = _recorder(request)
    marker = request.node.get_closest_marker("colour_fidelity")
    defaults: dict[str, Any] = dict(marker.kwargs) if marker else {}

    def measure(image: str | os.PathLike[str], **options: Any) -> ColourFidelity:
        kwargs = {**defaults, **options}
        # the image-reading and judging options may be given one by one (layer="beauty",
        # size="n"), or as their records (read=, judge=)
        for record, name in ((ReadOptions, "read"), (JudgeOptions, "judge")):
            given = {f.name for f in fields(record)} & kwargs.keys()
            if given:
                kwargs[name] = record(**{k: kwargs.pop(k) for k in sorted(given)})
        report = audit_image(image, **kwargs)
        name = os.fspath(image)
        record_property(f"{name}:mean_delta_e", f"{report.mean_delta_e:.4f}")
        record_property(f"{name}:max_delta_e", f"{report.max_delta_e:.4f}")
        if report.prediction is not None and report.prediction.dmap_points is not None:
            record_property(f"{name}:dmap_points", f"{report.prediction.dmap_points:.4f}")
        return ColourFidelity(report)

    return measure


__all__ = ["ColourFidelity", "colour_fidelity"]
