"""Tests of fidelity.chart: reading images and finding the chart."""
