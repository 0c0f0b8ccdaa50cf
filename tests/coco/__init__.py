"""Tests of fidelity.coco: the COCO benchmark."""
