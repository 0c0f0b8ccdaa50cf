"""Tests of fidelity.scene: the chart scenes for simulators."""
