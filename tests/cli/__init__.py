"""Tests of fidelity.cli: the command line."""
