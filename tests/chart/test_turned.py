"""The turned chart's shipped coverage (fidelity/data/turned/coverage.npz, issue 59)."""

from __future__ import annotations

import numpy as np

from fidelity.chart import turned


def test_shipped_coverage_is_the_computed_one():
    """The file every ``fidelity check`` reads holds exactly what the geometry computes (a
    change of the geometry or of the sampling rule makes this fail: write it again with
    ``python -c "from fidelity.chart import turned; turned.write_coverage_file()"``)."""
    shipped = turned._shipped_coverage(turned.CALIBRATION_GEOMETRY)
    assert shipped is not None
    for got, want in zip(shipped, turned._compute_coverage(turned.CALIBRATION_GEOMETRY),
                         strict=True):
        assert got.dtype == want.dtype and np.array_equal(got, want)


def test_another_geometry_is_computed_not_read():
    """A geometry other than the file's is never read from it: its coverage is computed."""
    other = turned.TurnedChart(size=(96, 128), pitch_px=18.0)
    assert turned._shipped_coverage(other) is None
    labels, mixed, samples = turned._coverage(other)
    assert labels.shape == (96, 128) and samples.shape == (mixed.size, 16)
