"""The sweep on a real Ray cluster (a head and a second node started here) equals the local run.

The cluster is started with ``ray start --head`` and ``ray start --address`` in a private
temporary folder on free ports, and stopped by ending exactly the processes it started (found
by that folder in their command lines, and their children): ``ray stop`` would end every Ray
process on the machine, other users' clusters too.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from fidelity.coco.sweep import ModelSpec, SweepStore

# among the longest files of the suite: started first, so that a parallel run does not end on it
pytestmark = pytest.mark.early

REPO = Path(__file__).resolve().parents[2]
GRID = (["contrast-inc", "contrast-dec"], [0, 3, 6])  # 8-bit tables: quick to build
IMAGES = 12


WORKER_PORTS = 41  # each node's worker port range: --min-worker-port .. +40


def _bindable(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _free_port_block(n: int) -> int:
    """The first of ``n`` consecutive ports free now, below the kernel's ephemeral range.

    Ports the kernel hands out (``bind(0)``) are its ephemeral ones: once closed, the same
    port can go to any outgoing connection (Ray's own among them) before ``ray start`` binds
    it, and a worker range counted up from one of them can cover another's port. A block
    below that range, each port of it tried, has neither problem.
    """
    low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    rng = random.Random()
    for _ in range(200):
        base = rng.randrange(10000, max(10001, low - n))
        if all(_bindable(q) for q in range(base, base + n)):
            return base
    pytest.fail(f"no {n} consecutive free ports between 10000 and {low}")


def _processes() -> dict[int, tuple[int, str]]:
    out = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{d}/cmdline").read_bytes().replace(b"\0", b" ").decode(
                errors="replace")
            stat = Path(f"/proc/{d}/stat").read_text()
        except OSError:
            continue
        out[int(d)] = (int(stat.rsplit(")", 1)[1].split()[1]), cmd)
    return out


def _cluster_processes(mark: str) -> dict[int, str]:
    """Processes whose command line names ``mark`` (the cluster's folder), and descendants."""
    procs = _processes()
    mine = {pid for pid, (_, cmd) in procs.items() if mark in cmd and pid != os.getpid()}
    grew = True
    while grew:
        grew = False
        for pid, (ppid, _) in procs.items():
            if ppid in mine and pid not in mine:
                mine.add(pid)
                grew = True
    return {pid: procs[pid][1] for pid in mine}


def _stop_cluster(mark: str) -> None:
    procs = _cluster_processes(mark)
    for pid in procs:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.time() + 5
    while time.time() < deadline and any(Path(f"/proc/{p}").exists() for p in procs):
        time.sleep(0.2)
    for pid in _cluster_processes(mark) | procs:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def _client_server_logs(folder: str) -> str:
    """The tails of the Ray Client servers' logs (why a per-client server died)."""
    logs = sorted(Path(folder).glob("session_*/logs/ray_client_server*"))
    return "\n".join(f"== {p.name}:\n{p.read_text(errors='replace')[-1500:]}" for p in logs)


@pytest.fixture(scope="module")
def cluster() -> Iterator[tuple[str, str, str]]:
    """A local Ray cluster of two nodes (1 CPU each) with a Ray Client server on the head;
    yields (head address, its folder, the ``ray://`` address)."""
    try:
        import ray  # noqa: F401
    except ImportError:
        pytest.skip("Ray cannot be imported here (pip install 'camera-fidelity[ray]')")
    if not Path("/proc").is_dir():
        pytest.skip("the cluster test finds its processes in /proc (Linux)")
    folder = tempfile.mkdtemp(prefix="fr-", dir="/tmp")  # short: Ray's socket paths are long
    base = _free_port_block(17 + 2 * WORKER_PORTS)
    p = list(range(base, base + 17))  # the nodes' own ports; then the two worker ranges
    workers = (base + 17, base + 17 + WORKER_PORTS)
    token = Path(folder) / "auth_token"  # the cluster's own token, not ~/.ray's
    token.write_text(secrets.token_hex(32))
    env = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN_PATH": str(token)}
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # for the drivers this test starts too
    ray_cli = [sys.executable, "-m", "ray.scripts.scripts", "start", "--num-cpus", "1",
               "--object-store-memory", str(100 * 2**20), "--disable-usage-stats"]

    def node_ports(q: list[int], worker: int) -> list[str]:
        return ["--node-manager-port", str(q[0]), "--object-manager-port", str(q[1]),
                "--min-worker-port", str(worker),
                "--max-worker-port", str(worker + WORKER_PORTS - 1),
                "--dashboard-agent-listen-port", str(q[2]), "--dashboard-agent-grpc-port",
                str(q[3]), "--metrics-export-port", str(q[4]), "--runtime-env-agent-port",
                str(q[5])]

    head = f"127.0.0.1:{p[0]}"
    try:
        for cmd in (ray_cli + ["--head", "--port", str(p[0]), "--temp-dir", folder,
                               "--include-dashboard", "false", "--dashboard-port", str(p[1]),
                               "--ray-client-server-port", str(p[16])]
                    + node_ports(p[2:8], workers[0]),
                    ray_cli + ["--address", head] + node_ports(p[8:14], workers[1])):
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
            if r.returncode != 0:
                pytest.fail(f"ray start failed: {r.stdout[-2000:]} {r.stderr[-2000:]}")
        yield head, folder, f"ray://127.0.0.1:{p[16]}"
    finally:
        _stop_cluster(folder)
        shutil.rmtree(folder, ignore_errors=True)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@pytest.fixture(scope="module")
def coco(shared: Path) -> tuple[Path, Path, Path]:
    return (shared / "coco/val2017", shared / "coco/annotations/instances_val2017_subset.json",
            shared / "models/yolox_nano.onnx")


@pytest.fixture(scope="module")
def local_sweep(coco, tmp_path_factory) -> SweepStore:
    """The grid swept locally, the reference both Ray sweeps are compared with (once)."""
    from fidelity.coco.sweep import run_sweep

    images, ann, model = coco
    return run_sweep([ModelSpec(model, IMAGES)], images, ann,
                     tmp_path_factory.mktemp("local-sweep"), *GRID, log=lambda s: None)


def _sweep_cli(coco: tuple[Path, Path, Path], out: Path, head: str) -> subprocess.Popen[str]:
    images, ann, model = coco
    return subprocess.Popen(
        [sys.executable, "-m", "fidelity", "sweep", "--models", f"{model}@{IMAGES}", "--images",
         str(images), "--annotations", str(ann), "--transforms", ",".join(GRID[0]),
         "--targets", ",".join(str(t) for t in GRID[1]), "--out", str(out), "--executor", "ray",
         "--address", head, "--workers", "2", "--no-progress"],
        cwd=REPO, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def _stored(out: Path) -> int:
    """Detections stored so far (a read-only look: no lock taken from the running sweep)."""
    import sqlite3

    p = out / "sweep.sqlite"
    if not p.is_file():
        return 0
    try:
        with contextlib.closing(sqlite3.connect(f"file:{p}?mode=ro", uri=True)) as db:
            return int(db.execute("SELECT COUNT(*) FROM detections").fetchone()[0])
    except sqlite3.OperationalError:  # not created yet
        return 0


def _wait_for(out: Path, n: int, proc: subprocess.Popen[str], timeout: float = 120) -> int:
    deadline = time.time() + timeout
    while time.time() < deadline and proc.poll() is None:
        got = _stored(out)
        if got >= n:
            return got
        time.sleep(0.05)
    return _stored(out)


def _new_images(log: str) -> int:
    return sum(int(m) for m in re.findall(r" new=(\d+) ", log))


def _assert_same(a: SweepStore, b: SweepStore) -> None:
    cells_a = {(c.model, c.transform, c.target): c for c in a.cells()}
    cells_b = {(c.model, c.transform, c.target): c for c in b.cells()}
    assert cells_a.keys() == cells_b.keys() and len(cells_a) == 5
    for key, c in cells_a.items():
        d = cells_b[key]
        assert (c.status, c.param, c.images, c.map, c.map50, c.map75, c.ap) == \
               (d.status, d.param, d.images, d.map, d.map50, d.map75, d.ap), key
        x, y = a.detections(*key), b.detections(*key)
        assert x.keys() == y.keys() and len(x) == IMAGES
        assert all(np.array_equal(x[i], y[i]) for i in x), key


@pytest.mark.shared
def test_ray_cluster_sweep_equals_local(cluster, coco, local_sweep, tmp_path) -> None:
    """The CLI on a two-node Ray cluster, 2 workers: one worker killed mid-run (Ray restarts it
    and retries its chunk), then the driver killed with SIGKILL and rerun; the final store
    equals a local run's cell by cell (scores and every detection), the rerun computes only
    what was not stored, and both nodes did work."""
    head, folder, _ = cluster
    local = local_sweep

    out = tmp_path / "ray"
    proc = _sweep_cli(coco, out, head)
    assert _wait_for(out, 8, proc) >= 8, proc.communicate()[1][-3000:]
    # the driver held still while the store is read and a worker killed: on a quick machine
    # the whole run can end within the status command's start-up, and a worker killed after
    # the last item is never restarted for work (both steps raced the run before)
    proc.send_signal(signal.SIGSTOP)
    try:
        status = subprocess.run([sys.executable, "-m", "fidelity", "sweep", "--status", "--out",
                                 str(out)], cwd=REPO, capture_output=True, text=True,
                                timeout=60)
        assert status.returncode == 0, status.stderr[-2000:]
        # per-cell progress of the live Ray run, from the claims the driver keeps in the store
        assert re.search(rf"under way: .* \d+ of {IMAGES} images stored; run on .* "
                         r"\(ray, 2 workers\)", status.stdout), status.stdout
        workers = [pid for pid, cmd in _cluster_processes(folder).items()
                   if cmd.startswith("ray::DetectorWorker")]
        assert len(workers) == 2, _cluster_processes(folder)
        os.kill(workers[0], signal.SIGKILL)  # a worker dies mid-run: Ray restarts it, retries
    finally:
        proc.send_signal(signal.SIGCONT)
    stdout, log = proc.communicate(timeout=240)
    assert proc.returncode == 0, log[-3000:]
    assert "5 cells done" in stdout, (stdout, log[-3000:])
    assert _new_images(log) == 5 * IMAGES, log[-3000:]  # every image computed and stored once
    ran = re.search(r"on (\d+) worker process(?:es)? \((\d+) nodes?\)", log)
    assert ran and int(ran.group(1)) >= 2 and int(ran.group(2)) == 2, log
    store = SweepStore(out)
    _assert_same(local, store)
    # the restarted worker did work: a process that was not running when one was killed ran
    # items (the killed one's retried item, or the next one); counting processes alone does
    # not show it, since a worker killed within its first item never reports that process
    ran_on = {int(w.rsplit(":", 1)[1]) for w in store.meta()["last_run"]["workers"]}
    assert ran_on - set(workers), (ran_on, workers, log)
    machine = store.meta()["machine"]
    assert machine["executor"] == "ray" and machine["workers"] == 2 and machine["nodes"] == 2, \
        machine

    # kill -9 of the driver, then a rerun: nothing lost, nothing stored computed again
    out2 = tmp_path / "ray-killed"
    proc = _sweep_cli(coco, out2, head)
    _wait_for(out2, 1, proc)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    kept = _stored(out2)
    assert 0 < kept < 5 * IMAGES, f"the kill came too late to test a resume ({kept} stored)"
    before = SweepStore(out2)
    stored_before = {k: before.detections(*k) for k in
                     [(c.model, c.transform, c.target) for c in local.cells()]}
    before.close()
    proc = _sweep_cli(coco, out2, head)
    stdout, log = proc.communicate(timeout=240)
    assert proc.returncode == 0, log[-3000:]
    assert _new_images(log) == 5 * IMAGES - kept, (kept, log[-3000:])
    again = SweepStore(out2)
    _assert_same(local, again)
    for key, dets in stored_before.items():  # what was stored stays as it was
        after = again.detections(*key)
        assert all(np.array_equal(after[i], d) for i, d in dets.items())
    assert again.claims() == []  # the run retired its claims


#: What Ray Client's proxy answers when the server process it starts for a client dies or is not
#: ready in time (Ray's ``ray/util/client/worker.py``: "Initialization failure from server").
_CLIENT_START_FAILURES = ("Starting Ray client server failed", "Initialization failure from server")


@pytest.mark.shared
def test_ray_client_sweep_equals_local(cluster, coco, local_sweep, tmp_path) -> None:
    """``--address ray://HOST:PORT`` (Ray Client: the driver outside the cluster, images and
    detections through the client connection) gives the local run's store."""
    _, folder, client = cluster
    local = local_sweep
    out = tmp_path / "client"
    stdout, log = _sweep_cli(coco, out, client).communicate(timeout=240)
    for wait in (5, 15, 30):
        if not any(failure in log for failure in _CLIENT_START_FAILURES):
            break
        # Ray's proxy starts one server process per client; on a loaded 2-core machine that
        # process can die or time out before it serves (a Ray start-up failure, not fidelity's:
        # fidelity's answer, exit 2 naming the address, is right). Again, a little later.
        time.sleep(wait)
        stdout, log = _sweep_cli(coco, out, client).communicate(timeout=240)
    assert "5 cells done" in stdout, (stdout, log[-3000:], _client_server_logs(folder))
    store = SweepStore(out)
    _assert_same(local, store)
    assert store.meta()["machine"]["executor"] == "ray"


@pytest.mark.shared
def test_ray_cluster_evaluate_and_validate_equal_local(cluster, coco, tmp_path) -> None:
    """evaluate and validate with --executor ray on the two-node cluster give the local
    scores (and, for validate, the same detections)."""
    from fidelity.coco.validate.store import ValidationStore
    from fidelity.coco.validate.suite import load_suite
    from fidelity.core.resources import resource_dir

    head, _, _ = cluster
    images, ann, model = coco
    base = [sys.executable, "-m", "fidelity", "evaluate", "--models", str(model), "--images",
            str(images), "--annotations", str(ann), "--limit", "10", "--no-progress"]
    out = {}
    for name, extra in (("local", ["--threads", "1"]),
                        ("ray", ["--executor", "ray", "--address", head, "--workers", "2"])):
        env = {**os.environ, "FIDELITY_CACHE": str(tmp_path / f"cache-{name}")}
        r = subprocess.run(base + extra + ["--json", str(tmp_path / f"{name}.json")], cwd=REPO,
                           env=env, capture_output=True, text=True, timeout=240)
        assert r.returncode == 0, r.stderr[-3000:]
        out[name] = json.loads((tmp_path / f"{name}.json").read_text())
    assert out["ray"]["executor"]["executor"] == "ray"
    for key in ("map", "map50", "map75", "ap", "detections"):
        assert out["ray"][key] == out["local"][key], key

    cams = tmp_path / "cameras"
    cams.mkdir()
    first = load_suite(resource_dir("cameras"))[0]
    shutil.copy(first.path, cams / first.path.name)
    stores = {}
    for name, extra in (("local", []),
                        ("ray", ["--executor", "ray", "--address", head, "--workers", "2"])):
        r = subprocess.run(
            [sys.executable, "-m", "fidelity", "validate", "--cameras", str(cams), "--models",
             f"{model}@4", "--images", str(images), "--annotations", str(ann), "--store",
             str(tmp_path / f"v-{name}"), "--out", str(tmp_path / f"r-{name}"),
             "--no-progress"] + extra, cwd=REPO, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        stores[name] = ValidationStore(tmp_path / f"v-{name}", create=False)
    local, remote = stores["local"], stores["ray"]
    assert remote.meta()["machine"]["executor"] == "ray"
    a = {(c.model, c.camera): c for c in local.cells()}
    b = {(c.model, c.camera): c for c in remote.cells()}
    assert a.keys() == b.keys() and len(a) == 2
    for key, c in a.items():
        assert (c.map, c.map50, c.ap, c.folds) == (b[key].map, b[key].map50, b[key].ap,
                                                   b[key].folds)
        x, y = local.detections(*key), remote.detections(*key)
        assert x.keys() == y.keys() and all(np.array_equal(x[i], y[i]) for i in x)


@pytest.mark.parametrize("extra, needle", [
    (["--address", "auto"], "--address is for --executor ray"),
    (["--workers", "2"], "the local executor runs one worker"),
])
def test_executor_options_need_ray(tmp_path, extra, needle) -> None:
    from click.testing import CliRunner

    from fidelity.cli import main
    from tests.coco.test_sweep import synthetic_coco

    images, ann, model = synthetic_coco(tmp_path / "data")
    r = CliRunner().invoke(main, ["sweep", "--models", str(model), "--images", str(images),
                                  "--annotations", str(ann), "--out", str(tmp_path / "o")]
                           + extra)
    assert r.exit_code == 2 and needle in r.output and "Traceback" not in r.output, r.output
