"""Tests of fidelity.pipeline: the pipelines of the commands."""
