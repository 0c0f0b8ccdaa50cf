"""Tests of fidelity.report: reports and records."""
