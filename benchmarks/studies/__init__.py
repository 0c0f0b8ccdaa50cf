"""Studies: measurements of what the tool states (standard errors, the coverage of its
uncertainty, the null perturbation, the finder's perspective bias) whose results are reports
under ``reports/`` that the documentation quotes. Each is run as ``python -m
benchmarks.studies.NAME`` with its own options (docs/benchmarks.md).
"""
