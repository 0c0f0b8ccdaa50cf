"""Charts in images: reading images and recordings, finding and locating the chart.

Modules: :mod:`~fidelity.chart.image` (EXR, HDR, TIFF, PNG, JPEG, raw mosaics),
:mod:`~fidelity.chart.recording` (ROS bags, MCAP), :mod:`~fidelity.chart.ocio` (OpenColorIO
colourspaces), :mod:`~fidelity.chart.read` (one image or frame as :class:`~fidelity.chart.read.ReadOptions` say),
:mod:`~fidelity.chart.find` (find the chart: a package, one module per step of its cascade),
:mod:`~fidelity.chart.bayer` (the CFA pattern of a raw mosaic, from the chart in it),
:mod:`~fidelity.chart.locate` (patch windows from corner centres). What is measured on the
located chart lives in :mod:`fidelity.measure`.
"""
