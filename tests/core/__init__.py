"""Tests of fidelity.core: the shared core."""
