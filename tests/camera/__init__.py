"""Tests of fidelity.camera: camera models and renders."""
