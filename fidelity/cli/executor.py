"""``--executor``, ``--address``, ``--workers``: where the COCO commands run their detectors."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    from fidelity.coco.executor import ExecutorOptions

F = TypeVar("F", bound=Callable[..., Any])


def executor_options(func: F) -> F:
    """Add the three executor options to a command (sweep, validate, evaluate)."""
    func = click.option(
        "--workers", type=click.IntRange(min=1), default=None,
        help="Ray workers (actors), each with its own ONNX session and image cache "
             "(default: one per CPU of the cluster, or per GPU where it has GPUs).")(func)
    func = click.option(
        "--address", default=None, metavar="auto|ray://HOST:10001|HOST:PORT",
        help="Ray cluster to use: auto (the one started with `ray start` here), a Ray Client "
             "address, or a head node's address (default: start Ray on this machine).")(func)
    func = click.option(
        "--executor", type=click.Choice(["local", "ray"]), default="local", show_default=True,
        help="local: this process runs the detector; ray: Ray actors on this machine or a "
             "cluster run it (pip install 'camera-fidelity[ray]'); the store and the results "
             "are the same.")(func)
    return func


def executor_from(executor: str, address: str | None, workers: int | None,
                  threads: int | None, provider: str) -> ExecutorOptions:
    """The :class:`fidelity.coco.executor.ExecutorOptions` of the command-line values."""
    from fidelity.coco.executor import ExecutorOptions

    return ExecutorOptions(executor, address, workers, threads, provider)
