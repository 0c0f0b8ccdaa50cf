"""Where the detector work of the COCO benchmark runs: in this process, or on a Ray cluster.

The long commands (``sweep``, ``validate``, ``evaluate``) cut their work into **work items**:
(model, pixel transform, chunk of image ids) of one cell. An **executor** runs items and hands
back their detections; the **driver** (:func:`run_cells`, in the command's process) claims
cells, submits their items, stores the detections as they come back and scores a cell when
its last image is stored. The driver is the only writer of the store, so resume, crash safety
and the store format do not depend on the executor.

``local`` (:class:`LocalExecutor`)
    One :class:`ChunkRunner` in this process: one ONNX session, one image cache. Items run one
    at a time, in plan order, when the driver asks for the next result.
``ray`` (:class:`RayExecutor`)
    ``workers`` Ray actors (:func:`ray_worker_class`), each a :class:`ChunkRunner` with its own
    ONNX session and image cache, reserving ``num_cpus = threads``; where the cluster has GPUs
    (and ``provider`` is auto or cuda) each also reserves ``num_gpus = min(1, GPUs / workers)``
    and runs the CUDA execution provider (default workers: one per GPU). Items go through Ray's
    :class:`ray.util.ActorPool`; an actor that dies is restarted by Ray and its item retried
    (``max_restarts``, ``max_task_retries``), so a killed worker costs only its chunk.

Data paths (no shared file system needed): the driver reads each image's JPEG bytes once,
checks them against the SHA-256 recorded in the store (:class:`fidelity.coco.store.ImageSet`)
and puts them in Ray's object store; a model file goes the same way (bytes, loaded into an
ONNX session from a private temporary file that is deleted at once). A sweep's transform table
(up to 48 MiB for saturation and hue) is built once per cell by a Ray task and shared through
the object store; a validation's emulation table is built by the driver and put there.

Every executor runs the same :meth:`ChunkRunner.run` on the same bytes, so detections, and
therefore every score, are identical whichever executor and however many workers ran them.
"""

from __future__ import annotations

import collections
import concurrent.futures  # noqa: TID253 (the executor's scoring thread)
import contextlib
import logging
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from fidelity.coco.dataset import PixelMap
from fidelity.coco.degradations import DEGRADATIONS, Degradation
from fidelity.coco.detectors import Detector
from fidelity.coco.jpeg import decode_jpeg, roundtrip_jpeg
from fidelity.coco.store import EvaluationStore, evaluation_store_dir, preprocessing_of
from fidelity.core.errors import FidelityError, InputFileError, InvalidValueError, unknown_name
from fidelity.core.fileio import file_sha256, remove_stale_temporaries
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.coco.dataset import PixelMap
    from fidelity.coco.store import EvaluationStore, ImageSet, LeaseKeeper

#: Executor names (``--executor``).
EXECUTORS: tuple[str, ...] = ("local", "ray")
#: The transform name of "no colour change" (work items of the baseline and of ``evaluate``).
IDENTITY = "baseline"
#: Cells of at most this many images map each image on its distinct colours (a sweep's
#: transform: :meth:`fidelity.coco.dataset.PixelMap.build`, ``direct``), or through a table of
#: their images' colours only (a validation's emulation), rather than a 2^24-entry table: a
#: 640 x 480 photo holds 40k-180k distinct colours, the table takes seconds to build.
DIRECT_IMAGES = 32
#: A ready transform of 8-bit images: a colour table (:class:`fidelity.coco.dataset.PixelMap`)
#: or a camera emulated with its optics and noise (:class:`fidelity.coco.imaging.CameraImaging`).
ImageMap = Callable[[np.ndarray], np.ndarray]
#: Images per work item: the local executor commits every 25 images (as before); Ray items
#: are smaller so that two or more workers share a cell's last images evenly.
CHUNK_IMAGES: dict[str, int] = {"local": 25, "ray": 8}
#: Work items kept in flight per Ray worker (enough to hide the round trip).
IN_FLIGHT_PER_WORKER = 2
#: Decoded images a runner keeps, in MiB of pixels (least recently used ones are dropped).
CACHE_MB = 4096
#: Seconds the Ray workers have to start (an autoscaling cluster may first add nodes).
WORKER_START_S = 300.0


@record
class ExecutorOptions:
    """How to run the work: ``kind`` (:data:`EXECUTORS`), Ray's ``address`` (None: start Ray
    on this machine; ``"auto"``: the running cluster; ``"ray://HOST:10001"``: Ray Client),
    ``workers`` (None: local 1, Ray every CPU (or GPU) of the cluster), onnxruntime
    ``threads`` per worker, ``provider`` (auto, cpu, cuda) and the image cache per worker
    (``cache_mb``)."""

    kind: str = "local"
    address: str | None = None
    workers: int | None = None
    threads: int | None = 1
    provider: str = "auto"
    cache_mb: int = CACHE_MB

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise unknown_name("executor", self.kind, EXECUTORS)
        if self.workers is not None and self.workers < 1:
            raise InvalidValueError(f"--workers {self.workers}: need at least 1")
        if self.kind == "local" and self.address is not None:
            raise InvalidValueError("--address is for --executor ray")
        if self.kind == "local" and self.workers not in (None, 1):
            raise InvalidValueError(f"--workers {self.workers}: the local executor runs one "
                                    "worker; use --executor ray for more")


@record
class ModelFile:
    """An ONNX detector as the executors see it: its file, name (the file stem) and SHA-256."""

    path: Path
    sha256: str

    @property
    def name(self) -> str:
        """The model's name: the file stem."""
        return self.path.stem

    @classmethod
    def from_path(cls, path: str | os.PathLike[str]) -> ModelFile:
        """A model file, hashed; a missing file is an input error."""
        p = Path(path)
        if not p.is_file():
            raise InputFileError(f"{p}: model file does not exist")
        return cls(p, file_sha256(p))


@record
class PixelTransform:
    """The 8-bit colour change of a cell: transform ``name`` at ``param``
    (:class:`fidelity.coco.dataset.PixelMap`), or a ready one (``table``: a validation's
    camera emulation, a 2^24-entry table or one of the run's own colours; not sent with work
    items); ``key`` names it uniquely;
    ``roundtrip``: JPEG re-encode with the original's settings after the change, as the
    transformed datasets are written (``evaluate`` reads the images as they are: False);
    ``direct``: map each image on its distinct colours rather than build a 2^24-entry table
    (the same codes; for a cell of at most :data:`DIRECT_IMAGES` images)."""

    key: str
    name: str
    param: float | None = None
    roundtrip: bool = True
    table: ImageMap | None = field(default=None, compare=False, repr=False)
    direct: bool = False

    @classmethod
    def of(cls, name: str, param: float | None, roundtrip: bool = True,
           images: int | None = None) -> PixelTransform:
        """The transform ``name`` at ``param`` (its key says both) for a cell of ``images``
        images (at most :data:`DIRECT_IMAGES`: ``direct``)."""
        direct = (images is not None and images <= DIRECT_IMAGES and name != IDENTITY
                  and name not in DEGRADATIONS)
        key = f"{name}@{param!r}" + ("~direct" if direct else "") if name != IDENTITY \
            else IDENTITY
        return cls(key, name, param, roundtrip, direct=direct)

    def build(self) -> Callable[[np.ndarray], np.ndarray] | None:
        """The callable that changes an (H, W, 3) uint8 image (None: no change)."""
        if self.table is not None:
            return self.table
        if self.name == IDENTITY:
            return None
        if self.name in DEGRADATIONS:  # blur and noise: spatial, not a table of colours
            if self.param is None:
                raise InvalidValueError(f"{self.name}: no level given")
            return Degradation(self.name, self.param)
        return PixelMap.build(self.name, self.param, direct=self.direct)

    def bare(self) -> PixelTransform:
        """The transform without its table (what a work item carries)."""
        return replace(self, table=None) if self.table is not None else self


@record
class WorkItem:
    """A chunk of one cell: detect ``image_ids`` with ``model`` after ``transform``. ``cell``
    is the store's key of the cell (e.g. ``(model, transform, target)``); ``clip``: boxes
    clipped to the image (False: as the network gives them, for Ultralytics' own metric)."""

    cell: tuple[Any, ...]
    model: ModelFile
    transform: PixelTransform
    image_ids: tuple[int, ...]
    clip: bool = True


@record
class ChunkResult:
    """What a worker hands back: the item, (image id, (n, 6) float32 detections) pairs in the
    item's order, the worker's seconds on it, which worker ran it (``node:pid``) and the CPU
    seconds its process spent on it (``cpu_seconds``: all its threads)."""

    item: WorkItem
    detections: tuple[tuple[int, np.ndarray], ...]
    seconds: float
    worker: str
    cpu_seconds: float = 0.0


# --------------------------------------------------------------------------------------------
# Worker side


class ChunkRunner:
    """A worker's state: one detector session (the last model), one transform (the last key)
    and a cache of decoded images (least recently used dropped beyond ``cache_mb``).

    :meth:`run` is the one place where a work item is computed, for every executor:
    decode (cached) -> transform -> JPEG round trip -> detector, the loading on the detector's
    prefetch thread ahead of the network (:meth:`fidelity.coco.detectors.Detector.detect_stream`).
    """

    def __init__(self, threads: int | None = 1, provider: str = "auto",
                 cache_mb: int = CACHE_MB) -> None:
        self.threads = threads
        self.provider = provider
        self.cache_bytes = int(cache_mb) << 20
        self._detector: Any = None
        self._model: ModelFile | None = None
        self._transform_key: str | None = None
        self._transform: Callable[[np.ndarray], np.ndarray] | None = None
        self._images: collections.OrderedDict[int, tuple[np.ndarray, Any]] = \
            collections.OrderedDict()
        self._held = 0

    def detector(self, model: ModelFile, path: Callable[[], contextlib.AbstractContextManager[Path]]
                 ) -> Any:
        """The session of ``model`` (made from the file ``path()`` gives when it changes)."""
        if self._model != model:
            self._detector = None
            with path() as p:
                self._detector = Detector(p, threads=self.threads, provider=self.provider)
            self._model = model
        return self._detector

    def transform(self, spec: PixelTransform,
                  build: Callable[[PixelTransform], Callable[[np.ndarray], np.ndarray] | None]
                  ) -> Callable[[np.ndarray], np.ndarray] | None:
        """The callable of ``spec`` (built by ``build`` when the key changes)."""
        if self._transform_key != spec.key:
            self._transform = None
            self._transform = build(spec)
            self._transform_key = spec.key
        return self._transform

    def image(self, image_id: int, data: Callable[[int], bytes], name: str) -> tuple[np.ndarray, Any]:
        """Decoded pixels and JPEG settings of an image (cached)."""
        hit = self._images.get(image_id)
        if hit is not None:
            self._images.move_to_end(image_id)
            return hit
        hit = decode_jpeg(data(image_id), name)
        self._images[image_id] = hit
        self._held += hit[0].nbytes
        while self._held > self.cache_bytes and len(self._images) > 1:
            _, old = self._images.popitem(last=False)
            self._held -= old[0].nbytes
        return hit

    def cached(self, image_id: int) -> bool:
        """Whether an image is decoded in the cache."""
        return image_id in self._images

    def run(self, item: WorkItem, *,
            model_path: Callable[[], contextlib.AbstractContextManager[Path]],
            build: Callable[[PixelTransform], Callable[[np.ndarray], np.ndarray] | None],
            data: Callable[[int], bytes], names: Mapping[int, str] | None = None,
            worker: str = "local") -> ChunkResult:
        """Detect every image of ``item``; ``data(image_id)`` gives an image's JPEG bytes."""
        t0, c0 = time.perf_counter(), time.process_time()
        det = self.detector(item.model, model_path)
        fn = self.transform(item.transform, build)

        def load(i: int) -> np.ndarray:  # on the detector's one prefetch thread, in order
            rgb, settings = self.image(i, data, (names or {}).get(i, f"image {i}"))
            x = fn(rgb) if fn is not None else rgb
            return roundtrip_jpeg(x, settings) if item.transform.roundtrip else x

        out = tuple(det.detect_stream(item.image_ids, load, clip=item.clip))
        return ChunkResult(item, out, time.perf_counter() - t0, worker,
                           time.process_time() - c0)


# --------------------------------------------------------------------------------------------
# Executors


class Executor(Protocol):
    """What the driver (:func:`run_cells`) needs from an executor."""

    kind: str
    workers: int
    capacity: int

    def describe(self) -> dict[str, Any]:
        """Provenance: executor, workers, nodes, threads, provider (JSON)."""
        ...

    def describe_model(self, model: ModelFile) -> dict[str, Any]:
        """The detector's own description (:meth:`fidelity.coco.detectors.Detector.describe`)."""
        ...

    def submit(self, item: WorkItem, table: ImageMap | None = None) -> None:
        """Queue a work item (``table``: the transform's ready table, if it has one)."""
        ...

    def next_result(self) -> ChunkResult:
        """The next finished item (blocks; in any order)."""
        ...

    def pending(self) -> int:
        """Items submitted and not handed back yet."""
        ...

    def close(self) -> None:
        """Release workers and connections."""
        ...


@contextlib.contextmanager
def _same_path(path: Path) -> Iterator[Path]:
    yield path


class LocalExecutor:
    """Runs items in this process, one at a time, in the order submitted (module docstring)."""

    kind = "local"
    workers = 1
    capacity = 1

    def __init__(self, images: ImageSet, options: ExecutorOptions) -> None:
        self.images = images
        self.options = options
        self.runner = ChunkRunner(options.threads, options.provider, options.cache_mb)
        self._queue: collections.deque[tuple[WorkItem, ImageMap | None]] = \
            collections.deque()

    def describe(self) -> dict[str, Any]:
        """Executor ``local``, one worker, threads, provider."""
        return {"executor": "local", "workers": 1, "threads": self.options.threads,
                "provider": self.options.provider}

    def describe_model(self, model: ModelFile) -> dict[str, Any]:
        """Loads the session (it is the one the items use)."""
        info: dict[str, Any] = self.runner.detector(model, lambda: _same_path(model.path)
                                                    ).describe()
        return info

    def submit(self, item: WorkItem, table: ImageMap | None = None) -> None:
        """Queue an item; it runs when :meth:`next_result` asks for it."""
        self._queue.append((item, table))

    def next_result(self) -> ChunkResult:
        """Run the oldest queued item."""
        item, table = self._queue.popleft()
        spec = replace(item.transform, table=table) if table is not None else item.transform

        def build(_: PixelTransform) -> Callable[[np.ndarray], np.ndarray] | None:
            return spec.build()

        names = {i: self.images.file_name(i) for i in item.image_ids}
        return self.runner.run(item, model_path=lambda: _same_path(item.model.path),
                               build=build, data=self.images.read, names=names)

    def pending(self) -> int:
        """Queued items."""
        return len(self._queue)

    def close(self) -> None:
        """Nothing to release."""
        self._queue.clear()


def _build_transform(spec: PixelTransform) -> Callable[[np.ndarray], np.ndarray] | None:
    """Build a transform (a Ray task: the table is made once and shared by every worker)."""
    return spec.build()


def ray_worker_class() -> Any:
    """The Ray actor class of the workers (made on first use: Ray is imported only here).

    Each actor holds a :class:`ChunkRunner`. Ray restarts a dead actor up to 5 times and
    retries its unfinished call up to 3 times (``max_restarts``/``max_task_retries``).
    """
    global _WORKER_CLASS
    if _WORKER_CLASS is not None:
        return _WORKER_CLASS
    import ray

    @ray.remote(max_restarts=5, max_task_retries=3)
    class DetectorWorker:
        """A Ray actor running work items (see :func:`ray_worker_class`)."""

        def __init__(self, threads: int | None, provider: str, cache_mb: int) -> None:
            self.runner = ChunkRunner(threads, provider, cache_mb)
            self.where = f"{ray.get_runtime_context().get_node_id()[:8]}:{os.getpid()}"

        def node(self) -> str:
            return self.where

        def describe_model(self, model: ModelFile, blob: list[Any]) -> dict[str, Any]:
            info: dict[str, Any] = self.runner.detector(
                model, lambda: _model_from_bytes(model, ray.get(blob[0]))).describe()
            return info

        def run(self, item: WorkItem, blob: list[Any], transform: list[Any],
                images: dict[int, Any], names: dict[int, str]) -> ChunkResult:
            refs = {i: r for i, r in images.items() if not self.runner.cached(i)}
            fetched = dict(zip(refs, ray.get(list(refs.values())), strict=True)) if refs else {}

            def data(i: int) -> bytes:
                got: bytes = fetched[i] if i in fetched else ray.get(images[i])
                return got

            def build(_: PixelTransform) -> Callable[[np.ndarray], np.ndarray] | None:
                fn: Callable[[np.ndarray], np.ndarray] | None = ray.get(transform[0])
                return fn

            return self.runner.run(item, model_path=lambda: _model_from_bytes(
                item.model, ray.get(blob[0])), build=build, data=data,
                names=names, worker=self.where)

    _WORKER_CLASS = DetectorWorker
    return DetectorWorker


_WORKER_CLASS: Any = None


@contextlib.contextmanager
def _model_from_bytes(model: ModelFile, data: bytes) -> Iterator[Path]:
    """The model's bytes as a file of its own name in a private folder, deleted on exit
    (onnxruntime has read it by then): nothing is left behind on a worker."""
    with tempfile.TemporaryDirectory(prefix="fidelity-model-") as tmp:
        p = Path(tmp) / model.path.name
        p.write_bytes(data)
        yield p


class RayExecutor:
    """Runs items on Ray actors through :class:`ray.util.ActorPool` (module docstring)."""

    kind = "ray"

    def __init__(self, images: ImageSet, options: ExecutorOptions) -> None:
        try:
            import ray
            from ray.util import ActorPool
        except ImportError as exc:
            raise InvalidValueError("--executor ray needs Ray: pip install "
                                    "'camera-fidelity[ray]'") from exc
        self.images = images
        self.options = options
        self._ray: Any = ray
        self._started = not ray.is_initialized()
        if self._started:
            self._init(options)
        resources: dict[str, float] = self._ray.cluster_resources()
        gpus = int(resources.get("GPU", 0))
        use_gpu = gpus > 0 and options.provider in ("auto", "cuda")
        if options.provider == "cuda" and not gpus:
            raise InvalidValueError("--provider cuda: the Ray cluster has no GPU")
        threads = options.threads or 1
        room = gpus if use_gpu else int(resources.get("CPU", 1)) // threads
        self.workers = options.workers or max(1, room)
        # GPU: one worker per GPU, or several sharing each GPU (fractional num_gpus) so that
        # one worker's JPEG and transform work overlaps another's inference
        per_worker: dict[str, float] = (
            {"num_gpus": min(1.0, gpus / self.workers), "num_cpus": threads} if use_gpu
            else {"num_cpus": threads})
        self.capacity = IN_FLIGHT_PER_WORKER * self.workers
        cls = ray_worker_class()
        provider = "cuda" if use_gpu else ("cpu" if options.provider == "auto"
                                           else options.provider)
        self.actors = [cls.options(**per_worker).remote(threads, provider, options.cache_mb)
                       for _ in range(self.workers)]
        self.pool = ActorPool(self.actors)
        try:
            self.nodes = sorted(set(ray.get([a.node.remote() for a in self.actors],
                                            timeout=WORKER_START_S)))
        except ray.exceptions.GetTimeoutError:
            self.close()
            need = ", ".join(f"{v:g} {k.removeprefix('num_').upper()}"
                             for k, v in per_worker.items())
            have = ", ".join(f"{resources.get(k, 0):g} {k}" for k in ("CPU", "GPU"))
            raise InvalidValueError(
                f"--workers {self.workers}: the workers did not start within "
                f"{WORKER_START_S:g} s; each needs {need} and the Ray cluster has {have}"
            ) from None
        self.provider = provider
        self._images: dict[int, Any] = {}
        self._models: dict[str, Any] = {}
        self._transforms: collections.OrderedDict[str, Any] = collections.OrderedDict()
        self._pending = 0
        self._builder = ray.remote(num_cpus=0)(_build_transform)

    def _init(self, options: ExecutorOptions) -> None:
        ray = self._ray
        kwargs: dict[str, Any] = {"logging_level": "WARNING", "log_to_driver": False}
        if options.address is None:
            kwargs |= {"include_dashboard": False,
                       "num_cpus": (options.workers or os.cpu_count() or 1)
                       * (options.threads or 1)}

        quiet = logging.getLogger("ray._private.authentication_token_setup")
        level = quiet.level
        quiet.setLevel(logging.ERROR)  # a notice on every start, not about this run
        try:
            ray.init(address=options.address, **kwargs)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            hint = ("; a cluster with token authentication needs RAY_AUTH_MODE=token and its "
                    "token (RAY_AUTH_TOKEN_PATH) here too"
                    if str(options.address).startswith("ray://")
                    and os.environ.get("RAY_AUTH_MODE") != "token" else "")
            raise InvalidValueError(f"--address {options.address}: cannot connect to a Ray "
                                    f"cluster: {' '.join(str(exc).split())[:300]}{hint}"
                                    ) from exc
        finally:
            quiet.setLevel(level)

    def describe(self) -> dict[str, Any]:
        """Executor ``ray``, workers, the nodes they run on, threads, provider."""
        return {"executor": "ray", "workers": self.workers,
                "nodes": len({w.split(":")[0] for w in self.nodes}), "worker_ids": self.nodes, "threads": self.options.threads,
                "provider": self.provider, "ray": self._ray.__version__}

    def _model_ref(self, model: ModelFile) -> Any:
        ref = self._models.get(model.sha256)
        if ref is None:
            try:
                data = model.path.read_bytes()
            except OSError as exc:
                raise InputFileError(f"{model.path}: cannot read the model: {exc}") from exc
            ref = self._models[model.sha256] = self._ray.put(data)
        return ref

    def describe_model(self, model: ModelFile) -> dict[str, Any]:
        """Asked of the first worker (it loads the session)."""
        return dict(self._get(self.actors[0].describe_model.remote(model,
                                                                   [self._model_ref(model)])))

    def _transform_ref(self, spec: PixelTransform, table: ImageMap | None) -> Any:
        ref = self._transforms.get(spec.key)
        if ref is None:
            if table is not None:
                ref = self._ray.put(table)
            else:
                ref = self._builder.remote(spec.bare())
            self._transforms[spec.key] = ref
            while len(self._transforms) > 4:  # items in flight keep their own reference
                self._transforms.popitem(last=False)
        return ref

    def _image_ref(self, image_id: int) -> Any:
        ref = self._images.get(image_id)
        if ref is None:
            ref = self._images[image_id] = self._ray.put(self.images.read(image_id))
        return ref

    def submit(self, item: WorkItem, table: ImageMap | None = None) -> None:
        """Hand an item to the actor pool (queued by Ray's pool while every actor is busy)."""
        transform = [self._transform_ref(item.transform, table)]
        images = {i: self._image_ref(i) for i in item.image_ids}
        names = {i: self.images.file_name(i) for i in item.image_ids}
        blob = [self._model_ref(item.model)]
        self.pool.submit(lambda actor, it: actor.run.remote(it, blob, transform, images, names),
                         item)
        self._pending += 1

    def _get(self, ref: Any) -> Any:
        try:
            return self._ray.get(ref)
        except self._ray.exceptions.RayTaskError as exc:
            raise _cause(exc) from None

    def next_result(self) -> ChunkResult:
        """The next finished item, in the order they finish."""
        try:
            result: ChunkResult = self.pool.get_next_unordered()
        except self._ray.exceptions.RayTaskError as exc:
            raise _cause(exc) from None
        self._pending -= 1
        return result

    def pending(self) -> int:
        """Items submitted and not handed back yet."""
        return self._pending

    def close(self) -> None:
        """Kill the actors; shut Ray down if this executor started it."""
        for a in getattr(self, "actors", []):
            with contextlib.suppress(Exception):
                self._ray.kill(a)
        if self._started:
            self._ray.shutdown()


def _cause(exc: Exception) -> BaseException:
    """The worker's own exception behind a Ray task error (a FidelityError stays one line)."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, FidelityError):
        return cause
    return RuntimeError(f"a Ray worker failed: {' '.join(str(cause or exc).split())[:500]}")


def make_executor(images: ImageSet, options: ExecutorOptions) -> Executor:
    """The executor ``options.kind`` names, over ``images``."""
    if options.kind == "ray":
        return RayExecutor(images, options)
    return LocalExecutor(images, options)


# --------------------------------------------------------------------------------------------
# Driver


@record
class CellWork:
    """A cell for :func:`run_cells`: its store ``key``, a ``label`` for messages, the model,
    the transform (``table``: a callable giving its ready table, called only when the cell has
    images to run) and every image id it is scored on."""

    key: tuple[Any, ...]
    label: str
    model: ModelFile
    transform: PixelTransform
    image_ids: tuple[int, ...]
    table: Callable[[], ImageMap] | None = None
    clip: bool = True


class CellStore(Protocol):
    """What :func:`run_cells` needs from a store, for one kind of cell."""

    def done(self, cell: CellWork) -> bool:
        """Whether the cell is finished (on its image ids)."""
        ...

    def stored(self, cell: CellWork) -> set[int]:
        """Image ids whose detections are stored."""
        ...

    def add(self, cell: CellWork, rows: Sequence[tuple[int, np.ndarray]]) -> None:
        """Store detections (one transaction)."""
        ...

    def finish(self, cell: CellWork, seconds: float, new: int) -> None:
        """Score and record a cell whose detections are all stored (``new`` computed now)."""
        ...


@dataclass
class RunCounts:
    """What a driver run did: cells finished by it, cells finished by other runs while it
    waited, images computed (detections stored by this run), work items, the workers' seconds
    on them, the worker processes (``node:pid``), the run's wall ``seconds`` and the CPU
    seconds the workers' processes spent on the items."""

    cells: int = 0
    waited: int = 0
    images: int = 0
    items: int = 0
    worker_seconds: float = 0.0
    workers: set[str] = field(default_factory=set)
    seconds: float = 0.0
    worker_cpu_seconds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """The counts as a store's ``meta["last_run"]`` keeps them."""
        return {"cells": self.cells, "waited": self.waited, "images": self.images,
                "items": self.items, "worker_seconds": self.worker_seconds,
                "worker_cpu_seconds": self.worker_cpu_seconds,
                "workers": sorted(self.workers), "seconds": self.seconds}


@dataclass
class _Open:
    cell: CellWork
    t0: float
    left: int
    new: int = 0


class CellRun:
    """One run of :func:`run_cells`: the plan, the cells open and waiting, the queue of work
    items not yet submitted, the scoring thread and the counts (the steps are its methods).

    :meth:`run` takes the cells in the given order; at most ``executor.capacity`` items are in
    flight, so that claims stay close to the work. A cell claimed by another live run is left
    to it and waited for at the end (taken over if that run stops beating, see
    :meth:`fidelity.coco.store.ResultsStore.claim`).
    """

    def __init__(self, cells: Sequence[CellWork], executor: Executor, store: CellStore, *,
                 lease: LeaseKeeper | None = None, chunk_images: int | None = None,
                 progress: bool = False, poll_s: float = 2.0,
                 say: Callable[[str], None] | None = None,
                 background: bool | None = None) -> None:
        from tqdm import tqdm

        self.cells = cells
        self.executor = executor
        self.store = store
        self.lease = lease
        self.poll_s = poll_s
        self.say = say
        self.chunk = chunk_images or CHUNK_IMAGES.get(executor.kind, 25)
        self.counts = RunCounts()
        self.t_start = time.perf_counter()
        self.todo = [c for c in cells if not store.done(c)]
        #: image ids stored per cell key when the run started
        self.stored = {c.key: store.stored(c) for c in self.todo}
        total_images = sum(len(set(c.image_ids) - self.stored[c.key]) for c in self.todo)
        self.bar = tqdm(total=total_images, unit="img", disable=not progress,
                        dynamic_ncols=True, file=sys.stderr, smoothing=0.1)
        self.done_cells = len(cells) - len(self.todo)
        self.show()
        self.open_cells: dict[tuple[Any, ...], _Open] = {}
        self.waiting: list[CellWork] = []
        self.queue: collections.deque[tuple[CellWork, WorkItem, ImageMap | None]] = \
            collections.deque()
        threaded = executor.workers > 1 if background is None else background
        self.scorer = (concurrent.futures.ThreadPoolExecutor(1, "fidelity-score") if threaded
                       else None)
        self.scoring: dict[tuple[Any, ...], concurrent.futures.Future[None]] = {}

    def show(self) -> None:
        """The bar's text: cells finished of the plan."""
        self.bar.set_description_str(f"cells {self.done_cells}/{len(self.cells)}",
                                     refresh=False)

    def recorded(self, key: tuple[Any, ...]) -> None:
        """A cell is recorded in the store: release its claim and count it."""
        if self.lease is not None:
            self.lease.release(key)
        self.counts.cells += 1
        self.done_cells += 1
        self.show()
        self.bar.refresh()

    def reap(self, wait: bool = False) -> None:
        """Release the claims of cells the scoring thread has recorded (``wait``: all)."""
        for key, fut in list(self.scoring.items()):
            if wait or fut.done():
                fut.result()  # the thread's error, if any, is the run's
                del self.scoring[key]
                self.recorded(key)

    def finish(self, o: _Open) -> None:
        """Score and record a cell whose items are all back (on the scoring thread, if any)."""
        del self.open_cells[o.cell.key]
        if self.store.done(o.cell):  # finished by a run that took the cell over meanwhile
            self.recorded(o.cell.key)
            return
        seconds = time.perf_counter() - o.t0
        if self.scorer is None:
            self.store.finish(o.cell, seconds, o.new)
            self.recorded(o.cell.key)
        else:
            self.scoring[o.cell.key] = self.scorer.submit(self.store.finish, o.cell, seconds,
                                                          o.new)

    def start(self, cell: CellWork) -> bool:
        """Claim and queue a cell's items; False when another run holds it."""
        if self.lease is not None and not self.lease.claim(cell.key):
            return False
        if self.store.done(cell):  # finished by another run meanwhile
            if self.lease is not None:
                self.lease.release(cell.key)
            return True
        have = self.store.stored(cell)
        missing = [i for i in cell.image_ids if i not in have]
        o = self.open_cells[cell.key] = _Open(cell, time.perf_counter(), 0)
        if not missing:
            self.finish(o)  # e.g. a model's image limit lowered: re-scored, no inference
            return True
        table = cell.table() if cell.table is not None else None
        for s in range(0, len(missing), self.chunk):
            self.queue.append((cell, WorkItem(cell.key, cell.model, cell.transform.bare(),
                                              tuple(missing[s:s + self.chunk]), cell.clip),
                               table))
            o.left += 1
        return True

    def collect(self) -> None:
        """Store the next finished item's detections; finish its cell when it was the last."""
        self.reap()
        r = self.executor.next_result()
        o = self.open_cells[r.item.cell]
        self.store.add(o.cell, r.detections)
        o.left -= 1
        o.new += len(r.detections)
        c = self.counts
        c.images += len(r.detections)
        c.items += 1
        c.worker_seconds += r.seconds
        c.worker_cpu_seconds += r.cpu_seconds
        c.workers.add(r.worker)
        self.bar.update(len(r.detections))
        if o.left == 0:
            self.finish(o)

    def pump(self) -> None:
        """Submit queued items up to the executor's capacity, then collect one result."""
        while self.queue and self.executor.pending() < self.executor.capacity:
            _, item, table = self.queue.popleft()
            self.executor.submit(item, table)
        if self.executor.pending():
            self.collect()

    def drain(self) -> None:
        """Run until nothing is queued or in flight."""
        while self.executor.pending() or self.queue:
            self.pump()

    def run_planned(self) -> None:
        """Every cell not finished when the run started, in order; claimed ones wait."""
        for cell in self.todo:
            if not self.start(cell):
                self.waiting.append(cell)
                continue
            while self.queue:
                self.pump()
            while self.executor.pending() >= self.executor.capacity:
                self.collect()
        self.drain()
        self.reap(wait=True)

    def run_waiting(self) -> None:
        """Wait for the cells other runs hold: count those they finish, take over the rest
        when their claims lapse."""
        announced = False
        while self.waiting:
            still = []
            for cell in self.waiting:
                if self.store.done(cell):
                    self.done_cells += 1
                    self.counts.waited += 1
                    self.show()
                    self.bar.update(len(set(cell.image_ids) - self.stored.get(cell.key, set())))
                elif self.start(cell):
                    self.drain()
                    self.reap(wait=True)
                else:
                    still.append(cell)
            self.waiting = still
            if self.waiting:
                if not announced and self.say is not None:
                    self.say(f"waiting for {len(self.waiting)} cells claimed by another run on "
                             "this store (taken over if it stops)")
                    announced = True
                time.sleep(self.poll_s)

    def run(self) -> RunCounts:
        """Run every cell (the planned ones, then those other runs held); the counts."""
        try:
            self.run_planned()
            self.run_waiting()
        finally:
            if self.scorer is not None:
                self.scorer.shutdown(wait=True)
            self.bar.close()
            self.counts.seconds = time.perf_counter() - self.t_start
        return self.counts


def run_cells(cells: Sequence[CellWork], executor: Executor, store: CellStore, *,
              lease: LeaseKeeper | None = None, chunk_images: int | None = None,
              progress: bool = False, poll_s: float = 2.0,
              say: Callable[[str], None] | None = None,
              background: bool | None = None) -> RunCounts:
    """Run every cell: claim, submit its missing images in chunks, store, finish
    (:class:`CellRun`).

    Cells are taken in the given order; at most ``executor.capacity`` items are in flight, so
    that claims stay close to the work. A cell claimed by another live run is left to it and
    waited for at the end (taken over if that run stops beating, see
    :meth:`fidelity.coco.store.ResultsStore.claim`). ``progress``: one bar for the whole plan
    (images done, rate, ETA; cells in its text), on stderr.

    ``background`` (default: for executors with more than one worker): a finished cell is
    scored (``store.finish``) on a thread of its own, so that the workers get new items while
    the driver scores; ``store.finish`` must then use a store connection of that thread (the
    sweep's and the validation's do). The claim is released once the cell is recorded.
    """
    return CellRun(cells, executor, store, lease=lease, chunk_images=chunk_images,
                   progress=progress, poll_s=poll_s, say=say, background=background).run()


class EvaluationCells:
    """An evaluation store as :func:`run_cells` sees it (a :class:`CellStore`): one cell,
    never finished (:func:`detect_images` reads the detections back), detections by image."""

    def __init__(self, store: EvaluationStore) -> None:
        self.store = store

    def done(self, cell: CellWork) -> bool:
        """Never: the stored images decide what is left."""
        return False

    def stored(self, cell: CellWork) -> set[int]:
        """Image ids whose detections are stored."""
        return self.store.stored_images()

    def add(self, cell: CellWork, rows: Sequence[tuple[int, np.ndarray]]) -> None:
        """Store detections (one transaction)."""
        self.store.add_detections(rows)

    def finish(self, cell: CellWork, seconds: float, new: int) -> None:
        """Nothing to score."""


@record
class Detections:
    """What :func:`detect_images` found: detections by image id, the detector's description,
    the images computed now (``new``; the others came from the store of an earlier run), the
    seconds the detection took and the executor's provenance."""

    detections: dict[int, np.ndarray]
    detector: dict[str, Any]
    new: int
    seconds: float
    executor: dict[str, Any]
    store: Path


def detect_images(model: ModelFile | str | os.PathLike[str], images: ImageSet,
                  ids: Sequence[int],
                  options: ExecutorOptions, *, store_base: str | os.PathLike[str] | None = None,
                  progress: bool = False) -> Detections:
    """Run one detector over images as they are (no transform, no re-encoding), resumably;
    boxes as the network gives them, not clipped to the image (``evaluate`` clips them for COCO
    AP and keeps them for Ultralytics' metric).

    Detections are stored per image as they come back, in an
    :class:`fidelity.coco.store.EvaluationStore` named by the model, provider and image set
    (:func:`fidelity.coco.store.evaluation_store_dir` under ``store_base``), so a killed run
    started again computes only the images it had not stored, and a repeated one none.
    """
    m = model if isinstance(model, ModelFile) else ModelFile.from_path(model)
    ex = make_executor(images, options)
    try:
        where = ex.describe()
        info = ex.describe_model(m)
        folder = evaluation_store_dir(m.sha256, options.provider, images.fingerprint(),
                                      store_base, preprocessing=preprocessing_of(info))
        store = EvaluationStore(folder)
    except BaseException:
        ex.close()
        raise
    try:
        remove_stale_temporaries(folder)
        store.register_model(m.name, m.path.name, m.sha256, None, info)
        cell = CellWork(("evaluate",), m.name, m, PixelTransform.of(IDENTITY, None, False),
                        tuple(ids), clip=False)
        counts = run_cells([cell], ex, EvaluationCells(store), progress=progress)
        store.set_meta("last_run", where | counts.to_json())
        dets = store.detections(ids)
    finally:
        ex.close()
        store.close()
    return Detections(dets, info, counts.images, counts.seconds, where, folder)
