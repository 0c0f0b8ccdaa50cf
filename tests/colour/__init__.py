"""Tests of fidelity.colour: colour science."""
