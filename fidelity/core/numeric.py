"""Small numeric helpers that give numpy's results without numpy's slow paths.

:func:`numpy.median` checks its result for NaN through ``numpy.ma`` (``np.ma.isMaskedArray``),
so its first call imports the masked-array package, about 20 ms of a process that needs no
masked array (``fidelity check`` and every measurement). :func:`median` computes the same
number the same way (the same partition, the same :func:`numpy.mean` of the middle values)
without that import.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def median(values: ArrayLike) -> float:
    """The median of all of ``values`` (flattened), equal to ``float(np.median(values))``.

    Parameters
    ----------
    values
        Numbers of any shape.

    Returns
    -------
    float
        The middle value (the mean of the two middle ones for an even count), computed as
        :func:`numpy.median` computes it, bit for bit; NaN when any value is NaN. An empty
        or non-floating input is passed to :func:`numpy.median` itself.
    """
    a = np.asarray(values)
    if a.size == 0 or a.dtype.kind != "f":
        return float(np.median(a))
    a = a.ravel()
    n = a.size
    half = n // 2
    # numpy.median's partition: the middle order statistics and the largest (NaN sorts last)
    part = np.partition(a, [half - 1, half, -1] if n % 2 == 0 else [half, -1])
    if np.isnan(part[-1]):
        return float(part[-1])
    middle = part[half - 1:half + 1] if n % 2 == 0 else part[half:half + 1]
    return float(np.mean(middle))


__all__ = ["median"]
