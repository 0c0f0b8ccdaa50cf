"""Tests of fidelity.measure: the measurements on a located chart."""
