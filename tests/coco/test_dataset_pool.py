"""``fidelity dataset``'s workers (issue 30, requirement 6): one pool for every subset of a grid,
no more workers than images, and the pull_mean kernel chosen for the run's size; the files are
those a single process writes."""

from __future__ import annotations

import hashlib
import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fidelity.coco import dataset
from fidelity.coco.dataset import (
    NUMBA_MIN_IMAGES,
    list_images,
    pool_size,
    run_kernel,
    write_grid,
)

ROOT = Path(__file__).resolve().parents[2]


def _folder(tmp_path: Path, n: int) -> list[Path]:
    src = tmp_path / "src"
    src.mkdir()
    rng = np.random.default_rng(0)
    for i in range(n):
        y, x = np.mgrid[0:48, 0:64]
        img = np.stack([x / 64, y / 48, 0.5 + 0.4 * np.sin(x / 5.0 + i)], -1)
        img = np.clip(img + rng.normal(0, 0.05, img.shape), 0, 1)
        buf = io.BytesIO()
        Image.fromarray(np.round(img * 255).astype(np.uint8)).save(buf, "JPEG", quality=80)
        (src / f"{i:03d}.jpg").write_bytes(buf.getvalue())
    return list_images(src)


def _digests(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*.jpg"))}


def test_pool_is_no_larger_than_the_folder() -> None:
    assert pool_size(8, 3) == 3
    assert pool_size(2, 100) == 2
    assert pool_size(4, 0) == 1
    assert dataset.start_workers(8, 1, ["pull_mean"]) is None  # one image: this process


def test_small_runs_take_the_numpy_kernel(monkeypatch) -> None:
    monkeypatch.delenv("FIDELITY_PULL_MEAN_KERNEL", raising=False)
    assert run_kernel(NUMBA_MIN_IMAGES - 1) == "numpy"
    assert run_kernel(NUMBA_MIN_IMAGES) == dataset.pull_mean_kernel("auto")
    monkeypatch.setenv("FIDELITY_PULL_MEAN_KERNEL", "numpy")
    assert run_kernel(10**6) == "numpy"


def test_grid_starts_workers_once_and_writes_what_one_process_writes(tmp_path, monkeypatch
                                                                      ) -> None:
    files = _folder(tmp_path, 5)
    started: list[int] = []
    real = dataset.start_workers

    def counting(workers: int, images: int, transforms: object) -> object:
        pool = real(workers, images, transforms)  # type: ignore[arg-type]
        started.append(0 if pool is None else pool_size(workers, images))
        return pool

    monkeypatch.setattr(dataset, "start_workers", counting)
    cells = (["pull_mean", "contrast-inc"], [0, 2, 3])
    write_grid(files, tmp_path / "pooled", *cells, workers=3, progress=False)
    assert started == [3]  # one pool for the 5 subsets
    write_grid(files, tmp_path / "serial", *cells, workers=1, progress=False)
    pooled, serial = _digests(tmp_path / "pooled"), _digests(tmp_path / "serial")
    assert len(pooled) == 5 * 5 and pooled == serial


def test_a_small_pull_mean_run_does_not_import_numba(tmp_path) -> None:
    """A whole process writing 3 images; its pull_mean files equal numba's (when installed)."""
    files = _folder(tmp_path, 3)
    code = ("import sys\n"
            "from pathlib import Path\n"
            "from fidelity.coco.dataset import list_images, write_transformed_dataset\n"
            "write_transformed_dataset(list_images(sys.argv[1]), sys.argv[2], 'pull_mean', 3,"
            " workers=2, progress=False)\n"
            "print('numba' in sys.modules)\n")
    env = {k: v for k, v in os.environ.items() if k != "FIDELITY_PULL_MEAN_KERNEL"}
    env["PYTHONPATH"] = str(ROOT)
    out = subprocess.run([sys.executable, "-c", code, str(files[0].parent),
                          str(tmp_path / "small")], capture_output=True, text=True, env=env,
                         cwd=ROOT, check=True)
    assert out.stdout.strip() == "False"
    pytest.importorskip("numba")
    env["FIDELITY_PULL_MEAN_KERNEL"] = "numba"
    subprocess.run([sys.executable, "-c", code, str(files[0].parent), str(tmp_path / "numba")],
                   capture_output=True, text=True, env=env, cwd=ROOT, check=True)
    assert _digests(tmp_path / "small") == _digests(tmp_path / "numba")
