"""The pipelines a command runs (check, audit and gate, compare, fit, qualify) and the records
they make."""
