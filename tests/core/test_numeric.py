"""fidelity.core.numeric: numpy's median, bit for bit, without importing numpy.ma."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from fidelity.core.numeric import median


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


def test_median_does_not_import_numpy_ma() -> None:
    code = ("import sys, numpy as np\n"
            "from fidelity.core.numeric import median\n"
            "median(np.arange(5.0)); median(np.arange(6.0))\n"
            "print('numpy.ma' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
