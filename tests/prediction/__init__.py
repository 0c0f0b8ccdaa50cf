"""Tests of fidelity.prediction: prediction tables and verdicts."""
