"""One run driver for the stores whose cells detectors fill: the COCO sweep and the validation.

A :class:`StoreRun` holds what such a run shares between its steps: the store, one store
connection per thread (:class:`fidelity.coco.store.ThreadStores`; a finished cell may be
scored on a thread of its own), the executor (:func:`fidelity.coco.executor.make_executor`)
and the run's claims on the store's cells (:class:`fidelity.coco.store.LeaseKeeper`). The
steps, in the order a run takes them:

1. ``with StoreRun(...) as run`` starts the executor and reads where it runs
   (:attr:`StoreRun.where`);
2. :meth:`StoreRun.record_machine` and :meth:`StoreRun.register_models` write the
   provenance (``meta["machine"]``, the registered models);
3. :meth:`StoreRun.start_leases` joins the store's leases, so that several runs share the cells;
4. :meth:`StoreRun.run` runs the cells (:func:`fidelity.coco.executor.run_cells`) through the
   caller's :class:`fidelity.coco.executor.CellStore` and writes ``meta["last_run"]``;

and leaving the ``with`` block retires the leases and closes the executor and the per-thread
connections. What differs between the sweep and the validation (the cells, their scoring and
log lines, their own provenance) stays with :func:`fidelity.coco.sweep.run_sweep` and
:func:`fidelity.coco.validate.colour.run_validation`.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Callable, Mapping, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from fidelity.coco.executor import make_executor, run_cells
from fidelity.coco.machine import cpu_description
from fidelity.coco.store import LEASE_STALE_S, ImageSet, LeaseKeeper, ResultsStore, ThreadStores

if TYPE_CHECKING:
    from fidelity.coco.executor import (
        CellStore,
        CellWork,
        Executor,
        ExecutorOptions,
        ModelFile,
        RunCounts,
    )

S = TypeVar("S", bound=ResultsStore)


class StoreRun(Generic[S]):
    """A run of detectors over the cells of one results store (module docstring).

    Parameters
    ----------
    store
        The run's store (this thread's connection).
    reopen
        Opens another connection to the same store (one per scoring thread).
    images
        The run's annotated images (checked against the store by the caller).
    options
        Where the detectors run (:class:`fidelity.coco.executor.ExecutorOptions`).
    """

    def __init__(self, store: S, reopen: Callable[[], S], images: ImageSet,
                 options: ExecutorOptions) -> None:
        self.store = store
        self.images = images
        self.options = options
        self.stores: ThreadStores[S] = ThreadStores(reopen)
        self.lease: LeaseKeeper | None = None
        self._executor: Executor | None = None
        #: the executor's provenance (:meth:`fidelity.coco.executor.Executor.describe`)
        self.where: dict[str, Any] = {}

    @property
    def executor(self) -> Executor:
        """The run's executor (started by ``with``)."""
        if self._executor is None:
            raise RuntimeError("StoreRun used outside its with block")
        return self._executor

    def __enter__(self) -> StoreRun[S]:
        self._executor = make_executor(self.images, self.options)
        try:
            self.where = self._executor.describe()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Retire the leases, close the executor and every per-thread connection."""
        if self.lease is not None:
            self.lease.close()
        if self._executor is not None:
            self._executor.close()
        self.stores.close()

    def record_machine(self, settings: Mapping[str, Any]) -> None:
        """``meta["machine"]``: platform, CPUs, processor and its kernel-choosing instructions
        (:func:`fidelity.coco.machine.cpu_description`), the run's ``settings`` (threads, ...)
        and where the executor runs; ``meta["machines"]``: every distinct machine (platform,
        CPUs, processor, instructions) that has run in this store, first to last, since a run
        resumed elsewhere may compute differently (int8 kernels differ with the instruction
        set)."""
        here = {"platform": platform.platform(), "cpus": os.cpu_count()} | cpu_description()
        self.store.set_meta("machine", here | dict(settings) | self.where)
        seen = self.store.meta().get("machines") or []
        if here not in seen:
            self.store.set_meta("machines", [*seen, here])

    def register_models(self, files: Sequence[ModelFile], limits: Sequence[int | None]) -> None:
        """Register every model file with its image limit (None: all images) and the
        executor's description of it (a conflicting earlier registration is an error)."""
        for f, limit in zip(files, limits, strict=True):
            self.store.register_model(f.name, f.path.name, f.sha256, limit,
                                      self.executor.describe_model(f))

    def start_leases(self, lease_s: float | None = None) -> None:
        """Join the store's leases (claims taken over after ``lease_s`` seconds of silence;
        None: :data:`fidelity.coco.store.LEASE_STALE_S`)."""
        self.lease = LeaseKeeper(self.store, self.where,
                                 stale_s=LEASE_STALE_S if lease_s is None else lease_s)

    def run(self, work: Sequence[CellWork], cells: CellStore, *, batch_commit: int,
            progress: bool, say: Callable[[str], None]) -> RunCounts:
        """Run the cells (:func:`fidelity.coco.executor.run_cells`; ``batch_commit`` images per
        work item of the local executor, the others' own) and record ``meta["last_run"]``."""
        chunk = batch_commit if self.options.kind == "local" else None
        counts = run_cells(work, self.executor, cells, lease=self.lease, chunk_images=chunk,
                           progress=progress, say=say)
        self.store.set_meta("last_run", self.where | counts.to_json())
        return counts


__all__ = ["StoreRun"]
