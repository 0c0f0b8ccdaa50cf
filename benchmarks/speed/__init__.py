"""The speed benchmarks: one module per benchmark, one runner, one result schema.

Each module times fidelity's code and its anchor (the library, method or earlier version it
replaces) side by side in one run, whole processes where the user runs a whole process (wall
time and max RSS of each), and ``python -m benchmarks.speed NAME`` writes the result to
``reports/benchmarks/NAME.json`` in the schema of :mod:`benchmarks.speed.record`
(``result.schema.json``). How a module is written: :mod:`benchmarks.speed.runner`.
"""
