"""``python -m benchmarks.speed [NAME ...] [--list] [--quick] [-p NAME=VALUE]``: run speed
benchmarks and write their results (:mod:`benchmarks.speed.runner`)."""

from benchmarks.speed.runner import main

raise SystemExit(main())
