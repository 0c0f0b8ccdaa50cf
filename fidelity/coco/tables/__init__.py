"""Worst-case loss tables from a sweep store: a shared floor, and a room per camera property.

Definitions (all derived from the finished cells of :mod:`fidelity.coco.sweep`):

* ΔmAP in points: ``dmap_points = 100 * (mAP_baseline - mAP_cell)`` (percentage points of
  COCO mAP@[.50:.95]); relative: ``dmap_relative = 100 * (mAP_baseline - mAP_cell) /
  mAP_baseline`` (percent of the baseline mAP). The baseline is the same model on the same
  images decoded and re-encoded without transform (ΔE 0). The same for ΔAP of person and bicycle.
* Worst case of a model at ΔE: the transform with the largest ``dmap_points`` among the
  finished, reachable cells at that ΔE (``worst_transform``); person and bicycle columns are
  worst cases of their own. Worst case of a size class (n, s, m, l, x): the largest value over
  the models of that size. Rows with a reachable transform not yet measured are partial.

The floor, whatever property the swept transforms change:

- :mod:`~fidelity.coco.tables.grid`: the cells of transform × level × detector against their
  baselines, one image count per model, standard errors;
- :mod:`~fidelity.coco.tables.worst`: the worst case over transforms per level, per model and
  per size class;
- :mod:`~fidelity.coco.tables.classes`: which classes a cell's loss comes from (rare classes,
  ``fidelity tables --explain``);
- :mod:`~fidelity.coco.tables.provenance`: the store's provenance schema, the words of scorers
  and standard errors, the runs a merge keeps;
- :mod:`~fidelity.coco.tables.build`: the :class:`~fidelity.coco.tables.build.Tables` of a
  store, and merged with an earlier ``tables.json``;
- :mod:`~fidelity.coco.tables.prediction`: the measured prediction table (the file format of
  :mod:`fidelity.prediction.tablefile`) with its provenance.

Colour's room:

- :mod:`~fidelity.coco.tables.colour`: the comparison with SAFE-COLOR's findings, the chart
  ΔE limits, ``tables.json`` (:class:`~fidelity.coco.tables.colour.TablesResult`,
  :func:`~fidelity.coco.tables.colour.tables_result`);
- :mod:`~fidelity.coco.tables.directional`: the direction-aware table (worst case per colour
  transform family).

A second property (sharpness, noise) plugs in as a sibling of ``colour.py``: its sweep's
store (the same :mod:`fidelity.coco.sweep` store, driver and executors) names its own
transforms in its grid, :func:`~fidelity.coco.tables.build.build_tables` makes its
:class:`~fidelity.coco.tables.build.Tables` and
:func:`~fidelity.coco.tables.prediction.prediction_table` its measured table; its module adds
what is its own (a comparison with its reference, its limits, its ``tables.json``). The level
is still named ``delta_e`` in the records, the JSON and the prediction-table format (colour's
axis, the only one so far): the property that first needs another axis gives them its name.
"""
