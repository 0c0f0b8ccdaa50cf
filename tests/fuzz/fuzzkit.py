"""The promise the fuzz suite checks, and the generators it draws inputs from.

The promise (README, docs/errors.md), for any input:

- the exit code is 0 (pass), 1 (fail) or 2 (input error), never 3 (a bug) and never a Python
  traceback;
- an input error prints exactly one line on stderr, ``fidelity: error: ...``, that names the
  input (its path, file name or option);
- the inputs are unchanged (same bytes) and no partial output is left behind (no temporary
  ``.NAME.*.tmp*`` file; after an input error, none of the outputs asked for exists).

Commands run in-process (``click.testing.CliRunner`` on ``fidelity.cli.main``), with
``--no-config`` so that no settings file of the working folder changes them.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import struct
import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from click.testing import CliRunner
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from fidelity.cli import main

#: Examples per property in the normal suite (fast) and behind ``-m fuzz`` (long).
FAST = 3
LONG = 150


def budget(examples: int) -> settings:
    """Hypothesis settings for a property run with ``examples`` examples: no deadline (a
    command takes 0.1-2 s), no example database (runs are independent), reproducible."""
    return settings(max_examples=examples, deadline=None, database=None,
                    derandomize=examples <= FAST, print_blob=True,
                    suppress_health_check=list(HealthCheck))


@dataclass(frozen=True)
class Outcome:
    """What a command did: exit code, stdout, stderr and the exception CliRunner caught."""

    args: tuple[str, ...]
    code: int
    stdout: str
    stderr: str
    exception: BaseException | None

    def __str__(self) -> str:
        return (f"fidelity {' '.join(self.args)} -> exit {self.code}\nstderr: {self.stderr!r}\n"
                f"stdout: {self.stdout[-400:]!r}\nexception: {self.exception!r}")


def run(*args: Any) -> Outcome:
    """Run ``fidelity --no-config ARGS`` in-process."""
    argv = tuple(str(a) if not isinstance(a, bytes) else a.decode("utf-8", "surrogateescape")
                 for a in args)
    r = CliRunner().invoke(main, ["--no-config", *argv], catch_exceptions=True)
    return Outcome(argv, r.exit_code, r.stdout, r.stderr, r.exception)


def fingerprint(paths: Iterable[Path]) -> dict[str, str]:
    """SHA-256 of every file at or under ``paths`` (folders walked), by path."""
    out: dict[str, str] = {}
    for p in paths:
        p = Path(p)
        files = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
        for f in files:
            if f.is_file():
                out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def leftovers(folders: Iterable[Path]) -> list[Path]:
    """Temporary files of :func:`fidelity.core.fileio.atomic_output` (``.NAME.XXXX.tmp...``) under
    ``folders``."""
    found: list[Path] = []
    for d in folders:
        d = Path(d)
        if d.is_dir():
            found.extend(q for q in d.rglob("*") if ".tmp" in q.name and q.name.startswith("."))
    return found


def assert_promise(outcome: Outcome, *, names: Sequence[str], before: dict[str, str],
                   outputs: Sequence[Path] = (), folders: Sequence[Path] = (),
                   codes: Sequence[int] = (0, 1, 2)) -> None:
    """Assert the promise (module docstring) for one run.

    ``names``: strings of which the error line must hold one (the input's path, file name or
    option); ``before``: :func:`fingerprint` of the inputs before the run; ``outputs``: files
    the command was asked to write (none may exist after an input error); ``folders``: where
    temporary files could be left; ``codes``: the exit codes that are right here.
    """
    assert outcome.code in codes, outcome
    assert outcome.code != 3, outcome
    for text in (outcome.stdout, outcome.stderr):
        assert "Traceback (most recent call last)" not in text, outcome
        assert "internal error" not in text, outcome
    if outcome.exception is not None:
        assert isinstance(outcome.exception, SystemExit), outcome
    lines = [ln for ln in outcome.stderr.splitlines() if ln.strip()]
    if outcome.code == 2:
        assert len(lines) == 1, outcome
        assert lines[0].startswith("fidelity: error: "), outcome
        assert any(n and n in lines[0] for n in names), (names, outcome)
        for p in outputs:
            assert not Path(p).exists(), (p, outcome)
    else:
        assert not any(ln.startswith("fidelity: error") for ln in lines), outcome
    after = fingerprint(Path(p) for p in before)
    assert after == before, ("an input changed", outcome)
    assert not leftovers(folders), (leftovers(folders), outcome)


# ----------------------------------------------------------------------------- documents

#: Any JSON value, small.
json_values = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(10**30), max_value=10**30)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=6),
    lambda children: st.lists(children, max_size=3)
    | st.dictionaries(st.text(max_size=6), children, max_size=3),
    max_leaves=6,
)


def paths_of(doc: Any, prefix: tuple[Any, ...] = (), depth: int = 8) -> list[tuple[Any, ...]]:
    """Every location in a JSON document (keys and indices from the top), ``depth`` deep."""
    out = [prefix]
    if depth <= 0:
        return out
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.extend(paths_of(v, (*prefix, k), depth - 1))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out.extend(paths_of(v, (*prefix, i), depth - 1))
    return out


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for k in path:
        doc = doc[k]
    return doc


def nested(depth: int) -> Any:
    """A list nested ``depth`` levels deep."""
    value: Any = 1
    for _ in range(depth):
        value = [value]
    return value


@st.composite
def mutated(draw: st.DrawFn, base: Any, extra_values: st.SearchStrategy[Any] | None = None
            ) -> Any:
    """``base`` with 1 to 3 random changes: a value replaced (by any JSON value, NaN, a huge
    number, a deep nesting), a field deleted or added, a list emptied or grown."""
    doc = copy.deepcopy(base)
    values = json_values if extra_values is None else (json_values | extra_values)
    deep: tuple[Any, ...] | None = None
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(paths_of(doc)))
        op = draw(st.sampled_from(["replace", "delete", "add", "empty", "grow", "deep"]))
        if not where:
            if op in ("replace", "delete"):
                doc = draw(values)
            continue
        parent = _get(doc, where[:-1])
        key = where[-1]
        if op == "replace":
            parent[key] = draw(values | st.sampled_from([math.nan, math.inf, -1, 0, 10**400,
                                                         1e308, -1e308, "", [], {}]))
        elif op == "delete":
            del parent[key]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=6))] = draw(values)
        elif op == "empty" and isinstance(parent[key], list | dict):
            parent[key] = type(parent[key])()
        elif op == "grow" and isinstance(parent[key], list) and parent[key]:
            parent[key] = parent[key] + parent[key][:1] * draw(st.integers(1, 30))
        elif op == "deep":
            deep = where
    if deep is not None:  # last: nothing walks the nesting afterwards
        try:
            _get(doc, deep[:-1])[deep[-1]] = nested(40)
        except (KeyError, IndexError, TypeError):
            pass
    return doc


def json_text(doc: Any) -> str:
    """``doc`` as JSON text (NaN and Infinity as JavaScript literals, as Python writes them)."""
    return json.dumps(doc, allow_nan=True)


@st.composite
def damaged_bytes(draw: st.DrawFn, data: bytes) -> bytes:
    """``data`` damaged: cut short, bytes overwritten, garbage inserted, bytes that are not
    UTF-8, or replaced by random bytes or nothing."""
    kind = draw(st.sampled_from(["truncate", "flip", "insert", "latin1", "random", "empty"]))
    if kind == "truncate" and data:
        return data[:draw(st.integers(0, len(data) - 1))]
    if kind == "flip" and data:
        b = bytearray(data)
        for _ in range(draw(st.integers(1, 8))):
            b[draw(st.integers(0, len(b) - 1))] = draw(st.integers(0, 255))
        return bytes(b)
    if kind == "insert":
        at = draw(st.integers(0, len(data)))
        return data[:at] + draw(st.binary(min_size=1, max_size=16)) + data[at:]
    if kind == "latin1":
        return data + b"\n# \xff\xfe caf\xe9\n"
    if kind == "random":
        return draw(st.binary(max_size=200))
    return b""


# ----------------------------------------------------------------------------- images

def write_image(path: Path, pixels: np.ndarray, fmt: str | None = None) -> Path:
    """Write ``pixels`` (H, W) or (H, W, C) with OpenImageIO in the format of ``path``'s
    suffix, in the array's own pixel type."""
    import OpenImageIO as oiio

    arr = np.ascontiguousarray(pixels if pixels.ndim == 3 else pixels[:, :, None])
    types = {np.dtype(np.uint8): oiio.UINT8, np.dtype(np.uint16): oiio.UINT16,
             np.dtype(np.float16): oiio.HALF, np.dtype(np.float32): oiio.FLOAT}
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], types[arr.dtype])
    assert out is not None and out.open(str(path), spec), oiio.geterror()
    assert out.write_image(arr), out.geterror()
    out.close()
    return path


#: (suffix, pixel types it stores) for generated images.
IMAGE_FORMATS: dict[str, tuple[str, ...]] = {
    ".png": ("uint8", "uint16"), ".tif": ("uint8", "uint16", "float16", "float32"),
    ".exr": ("float16", "float32"), ".jpg": ("uint8",), ".hdr": ("float32",),
}


@st.composite
def image_arrays(draw: st.DrawFn) -> tuple[str, np.ndarray]:
    """A suffix and an array it can store: odd sizes (1 x N, N x 1, up to 96), 1 to 5
    channels, each pixel type, values of every kind (NaN, +-Inf, negative, huge) for floats."""
    suffix = draw(st.sampled_from(sorted(IMAGE_FORMATS)))
    dtype = np.dtype(draw(st.sampled_from(IMAGE_FORMATS[suffix])))
    h, w = draw(st.integers(1, 96)), draw(st.integers(1, 96))
    channels = draw(st.sampled_from({".hdr": [3], ".jpg": [1, 3], ".png": [1, 2, 3, 4]}.get(
        suffix, [1, 2, 3, 4, 5])))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    if dtype.kind == "u":
        arr = rng.integers(0, np.iinfo(dtype).max, size=(h, w, channels), endpoint=True)
        return suffix, arr.astype(dtype)
    arr = rng.normal(0.3, 0.4, size=(h, w, channels))
    special = draw(st.sampled_from([None, np.nan, np.inf, -np.inf, -1.0, 1e30, 0.0]))
    if special is not None:
        mask = rng.random((h, w, channels)) < draw(st.sampled_from([0.01, 0.5, 1.0]))
        arr[mask] = special
    with np.errstate(over="ignore"):
        return suffix, arr.astype(dtype)


def png_header_only(width: int, height: int, padding: int = 0) -> bytes:
    """A PNG that declares ``width`` x ``height`` 8-bit RGB pixels but holds almost none (a
    decompression bomb's header): valid signature, IHDR and CRCs, a tiny IDAT and ``padding``
    bytes of a second one (OpenImageIO itself refuses a header that claims 10000 times the
    file's size; a padded one reaches fidelity's own pixel limit)."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    idat = zlib.compress(b"\x00" * 64)
    pad = chunk(b"IDAT", b"\x00" * padding) if padding else b""
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + pad
            + chunk(b"IEND", b""))


# ----------------------------------------------------------------------------- ONNX models

def yolox_cells(size: int) -> int:
    """Anchors of strides 8, 16, 32 for a square input of ``size`` pixels."""
    return sum((size // s) ** 2 for s in (8, 16, 32))


def onnx_model(path: Path, output: np.ndarray, *, size: int = 32, metadata: dict[str, str]
               | None = None, input_shape: Sequence[int | str] | None = None,
               outputs: int = 1) -> Path:
    """A detector stand-in: input ``images`` 1x3xSIZExSIZE float, output(s) the constant
    ``output`` (built with the ``onnx`` helper; onnxruntime runs it)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    out = np.asarray(output, dtype=np.float32)
    nodes = [helper.make_node("Constant", [], [f"out{k}"], value=numpy_helper.from_array(out))
             for k in range(outputs)]
    graph = helper.make_graph(
        nodes, "stand-in",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT,
                                       list(input_shape or [1, 3, size, size]))],
        [helper.make_tensor_value_info(f"out{k}", TensorProto.FLOAT, list(out.shape))
         for k in range(outputs)])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    for k, v in (metadata or {}).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    onnx.save(model, str(path))
    return path


def ultralytics_output(classes: int = 80, size: int = 32, boxes: int = 3, seed: int = 0,
                       special: float | None = None) -> np.ndarray:
    """A 1 x (4+C) x N Ultralytics output with ``boxes`` confident boxes (cx, cy, w, h in input
    pixels), optionally one value set to ``special`` (NaN, Inf)."""
    rng = np.random.default_rng(seed)
    n = yolox_cells(size)
    out = np.zeros((1, 4 + classes, n), dtype=np.float32)
    for k in range(min(boxes, n)):
        out[0, :4, k] = [rng.uniform(4, size - 4), rng.uniform(4, size - 4),
                         rng.uniform(2, size / 2), rng.uniform(2, size / 2)]
        out[0, 4 + int(rng.integers(0, classes)), k] = rng.uniform(0.2, 1.0)
    if special is not None:
        out[0, 4 + int(rng.integers(0, classes)), int(rng.integers(0, n))] = special
    return out


# ----------------------------------------------------------------------------- COCO

def coco_set(folder: Path, images: int = 3, seed: int = 0) -> tuple[Path, Path, dict[str, Any]]:
    """A small COCO set: ``images`` random 40x56 JPEGs in ``folder/img`` and their box
    annotations (the 80 COCO categories) in ``folder/ann.json``."""
    from PIL import Image

    from fidelity.coco.detectors import COCO80_CATEGORY_IDS, COCO80_NAMES

    rng = np.random.default_rng(seed)
    img_dir = folder / "img"
    img_dir.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {"images": [], "annotations": [],
                           "categories": [{"id": i, "name": n, "supercategory": "x"}
                                          for i, n in zip(COCO80_CATEGORY_IDS, COCO80_NAMES,
                                                          strict=True)]}
    for k in range(images):
        name = f"{k + 1:012d}.jpg"
        Image.fromarray(rng.integers(0, 256, (40, 56, 3), dtype=np.uint8)).save(
            img_dir / name, quality=90)
        doc["images"].append({"id": k + 1, "file_name": name, "width": 56, "height": 40})
        for j in range(2):
            x, y = float(rng.uniform(0, 30)), float(rng.uniform(0, 20))
            doc["annotations"].append({"id": 10 * k + j + 1, "image_id": k + 1,
                                       "category_id": COCO80_CATEGORY_IDS[j],
                                       "bbox": [x, y, 20.0, 15.0], "area": 300.0,
                                       "iscrowd": 0})
    ann = folder / "ann.json"
    ann.write_text(json.dumps(doc))
    return img_dir, ann, doc


#: A valid camera file's content (every stage used), as a mapping to mutate.
CAMERA: dict[str, Any] = {
    "name": "fuzz", "description": "a camera for the fuzz suite",
    "sensitivities": {"source": "Nikon 5100 (NPL)"},
    "exposure": {"mode": "gain", "ev": 0.5},
    "white_balance": {"method": "gains", "gains": [2.0, 1.0, 1.6]},
    "ccm": {"method": "matrix", "matrix": [[1.2, -0.1, -0.1], [-0.1, 1.2, -0.1],
                                           [-0.1, -0.1, 1.2]]},
    "tone": {"curve": "lut", "lut": [[0.0, 0.0], [0.5, 0.7], [1.0, 1.0]]},
    "noise": {"full_well": 9000, "read_noise": 4, "seed": 3},
    "quantisation": {"bits": 10},
    "vignetting": {"diagonal_fov_deg": 60},
}


def toml_text(doc: Any) -> str | None:
    """``doc`` as TOML (None: TOML cannot hold it, e.g. a null or a top level that is not a
    table)."""
    import tomli_w

    try:
        return tomli_w.dumps(doc)
    except (TypeError, ValueError, AttributeError):
        return None


def each(values: Iterable[Any], check: Callable[[Any], None]) -> None:
    """Run ``check`` on every value (a loop helper for parametrised corner cases)."""
    for v in values:
        check(v)
