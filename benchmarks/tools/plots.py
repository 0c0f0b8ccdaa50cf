"""The matplotlib helpers of the benchmark reports (Agg backend, no screen): a figure and its
PNG bytes (:func:`new_figure`, :func:`png_bytes`).

The tool's own reports draw their figures as SVG from the numbers (:mod:`fidelity.report.svg`),
so matplotlib is a benchmark and test requirement only (the ``test`` extra).
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Resolution of every PNG.
DPI = 110


def new_figure(width: float, height: float, nrows: int = 1, ncols: int = 1
               ) -> tuple[Figure, Any]:
    """A matplotlib figure and its axes (``plt.subplots``) on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, ncols, figsize=(width, height), layout="constrained")


def png_bytes(fig: Figure, dpi: int = DPI) -> bytes:
    """The figure as PNG bytes; the figure is closed. The margins come from the constrained
    layout of :func:`new_figure` (drawn once; a tight bounding box would draw every figure
    twice, half the time of a validation report)."""
    import matplotlib.pyplot as plt
    import numpy as np
    from PIL import Image

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    # Lossless and smaller (the reports embed their figures): no alpha channel where every
    # pixel is opaque, and Pillow's optimised zlib compression.
    rgba = np.asarray(Image.open(io.BytesIO(buf.getvalue())).convert("RGBA"))
    image = Image.fromarray(rgba[..., :3] if rgba[..., 3].min() == 255 else rgba)
    out = io.BytesIO()
    image.save(out, format="PNG", optimize=True)
    return out.getvalue()


__all__ = [
    "DPI",
    "new_figure",
    "png_bytes",
]
