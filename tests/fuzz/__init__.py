"""The long fuzz run (pytest -m fuzz)."""
