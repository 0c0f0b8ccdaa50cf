"""The matplotlib helpers of the COCO, validation and benchmark reports (Agg backend, no screen).

One place sets the backend and turns a figure into PNG bytes (:func:`new_figure`,
:func:`png_bytes`) and formats log axes (:func:`axes_plain_ticks`). The chart report's figures
(``check``, ``audit``, ``gate``, ``compare``) do not use matplotlib: they are SVG drawn from the
numbers by :mod:`fidelity.report.chartfigures`, so those commands never import it.
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.axes import Axes
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


def axes_plain_ticks(ax: Axes) -> None:
    """Tick labels as plain numbers on the log and symlog axes of ``ax`` (0.5, 1, 10 rather
    than 10^0); a symlog axis (linear below 1) gets ticks at 1, 2 and 5 per decade. Linear
    axes are left as they are."""
    from matplotlib.ticker import FuncFormatter, SymmetricalLogLocator

    for axis in (ax.xaxis, ax.yaxis):
        scale = axis.get_scale()
        if scale == "symlog":
            axis.set_major_locator(SymmetricalLogLocator(base=10, linthresh=1.0,
                                                         subs=[1.0, 2.0, 5.0]))
        if scale in ("log", "symlog"):
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


__all__ = [
    "DPI",
    "axes_plain_ticks",
    "new_figure",
    "png_bytes",
]
