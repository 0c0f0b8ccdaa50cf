"""Small numeric helpers that give numpy's results without numpy's slow paths.

:func:`numpy.median` checks its result for NaN through ``numpy.ma`` (``np.ma.isMaskedArray``),
so its first call imports the masked-array package, about 20 ms of a process that needs no
masked array (``fidelity check`` and every measurement). :func:`median` computes the same
number the same way (the same partition, the same :func:`numpy.mean` of the middle values)
without that import. :func:`numpy.percentile` does the same through ``numpy.unique``
(``np.ma.is_masked``); :func:`percentile` gives its number (the ``linear`` method) without it.
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


def percentile(values: ArrayLike, q: float) -> float:
    """The ``q``-th percentile of all of ``values`` (flattened), equal to
    ``float(np.percentile(values, q))`` (its default ``linear`` method, Hyndman and Fan's
    method 7).

    Parameters
    ----------
    values
        Numbers of any shape.
    q
        The percentile, in [0, 100].

    Returns
    -------
    float
        The value at the virtual index ``(n - 1) q / 100`` of the sorted values, linearly
        interpolated between its neighbours as :func:`numpy.percentile` interpolates
        (in the values' precision), bit for bit; NaN when any value is NaN. An empty or
        non-floating input, or ``q`` outside [0, 100], is passed to :func:`numpy.percentile`
        itself.
    """
    a = np.asarray(values)
    if a.size == 0 or a.dtype.kind != "f" or not 0.0 <= q <= 100.0:
        return float(np.percentile(a, q))
    a = a.ravel()
    n = a.size
    virtual = (n - 1) * float(np.true_divide(q, 100))
    if virtual >= n - 1:
        below = above = n - 1
    else:
        below = int(np.floor(virtual))
        above = below + 1
    part = np.partition(a, sorted({0, below, above, n - 1}))
    if np.isnan(part[-1]):
        return float(part[-1])
    lo, hi = part[below], part[above]
    gamma = virtual - below
    diff = hi - lo
    # numpy's _lerp: from the lower neighbour below gamma 0.5, from the upper one above
    return float(lo + diff * gamma if gamma < 0.5 else hi - diff * (1 - gamma))


__all__ = ["median", "percentile"]
