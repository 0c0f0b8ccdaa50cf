"""fidelity.core.numeric: numpy's median and percentile, bit for bit, without importing
numpy.ma."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from fidelity.core.numeric import median, percentile


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 10, 11, 64, 101])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_median_equals_numpy_bit_for_bit(n: int, dtype: type) -> None:
    rng = np.random.default_rng(n)
    for _ in range(20):
        a = rng.normal(0.0, 1.0, n).astype(dtype)
        assert median(a) == float(np.median(a))
        ties = np.round(a * 2).astype(dtype)  # repeated values
        assert median(ties) == float(np.median(ties))


def test_median_flattens_and_takes_lists() -> None:
    a = np.arange(12.0).reshape(3, 4)[:, ::-1]
    assert median(a) == float(np.median(a)) == 5.5
    assert median([3.0, 1.0, 2.0]) == 2.0
    assert median([1, 2, 3, 4]) == 2.5  # integers: numpy.median itself


def test_median_nan_and_empty_as_numpy() -> None:
    assert math.isnan(median(np.array([1.0, np.nan, 3.0])))
    with pytest.warns(RuntimeWarning):
        assert math.isnan(median(np.array([], np.float64)))


def test_median_and_percentile_do_not_import_numpy_ma() -> None:
    code = ("import sys, numpy as np\n"
            "from fidelity.core.numeric import median, percentile\n"
            "median(np.arange(5.0)); median(np.arange(6.0)); percentile(np.arange(7.0), 99)\n"
            "print('numpy.ma' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("n", [1, 2, 3, 5, 10, 101, 4097])
@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.float16])
def test_percentile_equals_numpy_bit_for_bit(n: int, dtype: type) -> None:
    rng = np.random.default_rng(n)
    for _ in range(10):
        a = rng.normal(0.0, 1.0, n).astype(dtype)
        ties = np.round(a * 2).astype(dtype)
        for q in (0.0, 1.0, 25.0, 50.0, 90.0, 99.0, 99.9, 100.0, float(rng.uniform(0, 100))):
            assert percentile(a, q) == float(np.percentile(a, q))
            assert percentile(ties, q) == float(np.percentile(ties, q))


def test_percentile_nan_empty_and_out_of_range_as_numpy() -> None:
    assert math.isnan(percentile(np.array([1.0, np.nan, 3.0]), 50.0))
    assert percentile(np.arange(12.0).reshape(3, 4), 99.0) == float(np.percentile(
        np.arange(12.0), 99.0))
    assert percentile([1, 2, 3, 4], 30.0) == float(np.percentile([1, 2, 3, 4], 30.0))
    with pytest.raises(ValueError):
        percentile(np.arange(3.0), 101.0)
