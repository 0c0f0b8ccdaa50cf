"""The test suite: one folder per package of fidelity (tests/chart/test_find.py tests
fidelity/chart/find), package-wide tests at the top."""
