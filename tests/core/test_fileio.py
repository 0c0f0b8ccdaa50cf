"""Atomic outputs: no partial files, never over an input, ordinary permissions."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from fidelity.core.errors import InputFileError
from fidelity.core.fileio import (
    atomic_output,
    check_outputs,
    json_ready,
    require_file,
    write_bytes_atomic,
    write_json_atomic,
    write_text_atomic,
)


def test_atomic_write_leaves_no_partial_file_on_error(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_output(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_an_output_whose_folder_is_a_file_is_an_input_error(tmp_path: Path) -> None:
    (tmp_path / "taken").write_text("a file")
    with pytest.raises(InputFileError, match="taken is a file, not a folder"):
        write_text_atomic(tmp_path / "taken" / "out.txt", "x")
    with pytest.raises(InputFileError, match="cannot write"):  # deeper: not a folder
        write_text_atomic(tmp_path / "taken" / "sub" / "out.txt", "x")
    assert (tmp_path / "taken").read_text() == "a file"


def test_outputs_follow_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        p = write_text_atomic(tmp_path / "sub" / "r.txt", "x")
    finally:
        os.umask(old)
    assert p.stat().st_mode & 0o777 == 0o644


def test_refuses_to_write_over_an_input(tmp_path: Path) -> None:
    src = tmp_path / "in.json"
    src.write_text("{}")
    with pytest.raises(InputFileError, match="over an input"), atomic_output(src, protect=[src]):
        pass
    assert src.read_text() == "{}"


def test_json_rejects_nan_and_require_file_names_the_problem(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        write_json_atomic(tmp_path / "x.json", {"a": float("nan")})
    assert not (tmp_path / "x.json").exists()
    with pytest.raises(InputFileError, match="does not exist"):
        require_file(tmp_path / "missing.png", "image")
    with pytest.raises(InputFileError, match="not a regular file"):
        require_file(tmp_path, "image")


def test_check_outputs_sees_through_links_and_relative_paths(tmp_path: Path, monkeypatch) -> None:
    src = tmp_path / "in.exr"
    src.write_bytes(b"x")
    (tmp_path / "link.exr").symlink_to(src)
    monkeypatch.chdir(tmp_path)
    for out in ("in.exr", "./in.exr", "link.exr", str(src)):
        with pytest.raises(InputFileError, match=r"--json names the input IMAGE \(.*in.exr\)"):
            check_outputs({"--json": out}, {"IMAGE": src})
    check_outputs({"--json": "new.json", "--html": None}, {"IMAGE": src, "--table": "name"})
    with pytest.raises(InputFileError, match="named by both --json and --junit"):
        check_outputs({"--json": "r.xml", "--junit": "./r.xml"})
    with pytest.raises(InputFileError, match="--html names a folder; give a file name"):
        check_outputs({"--html": tmp_path})
    assert src.read_bytes() == b"x"


def test_json_ready_makes_strict_json() -> None:
    """numpy scalars and arrays to Python, NaN/inf to null, keys to strings, records by their
    to_json; the result passes json.dumps(allow_nan=False) and keeps every finite value."""
    import json
    import math
    from dataclasses import dataclass

    import numpy as np

    @dataclass(frozen=True)
    class Rec:
        x: float

        def to_json(self) -> dict[str, float]:
            return {"x": self.x}

    obj = {1: np.float64(0.1), "a": [np.int64(3), np.bool_(True), (np.nan, -np.inf)],
           "arr": np.array([[1.5, np.nan]]), "p": Path("/a/b"), "rec": Rec(np.float32(2.5)),
           "neg_zero": -0.0, "none": None, "s": "text"}
    got = json_ready(obj)
    assert got == {"1": 0.1, "a": [3, True, [None, None]], "arr": [[1.5, None]],
                   "p": "/a/b", "rec": {"x": 2.5}, "neg_zero": -0.0, "none": None,
                   "s": "text"}
    assert type(got["1"]) is float and type(got["a"][0]) is int and type(got["a"][1]) is bool
    assert math.copysign(1.0, got["neg_zero"]) == -1.0  # -0.0 stays as written
    json.dumps(got, allow_nan=False)


def test_number_formatter() -> None:
    from fidelity.report.format import MISSING, number, words

    assert (number(0.125), number(0.125, 1), number(3), number(None), number("x")) == (
        "0.12", "0.1", "3", MISSING, "x")
    assert words({"python": "3.11", "cpus": 2, "load": [1.5, 2.0], "x": None}) == (
        "python 3.11, cpus 2, load 1.5, 2.0, x –")
    assert words({}) == MISSING


def test_check_outputs_protects_input_folders_and_stores(tmp_path: Path) -> None:
    """An output inside an input folder (existing or not: a rerun answers as the first run), or
    directly in a results store's folder, is refused; store subfolders are not."""
    from fidelity.core.fileio import check_output_folders

    images = tmp_path / "images"
    images.mkdir()
    (images / "one.jpg").write_bytes(b"jpeg")
    with pytest.raises(InputFileError, match=r"--json writes inside the input folder --images"):
        check_outputs({"--json": images / "one.jpg"}, {"--images": images})
    with pytest.raises(InputFileError, match="inside the input folder"):
        check_outputs({"--json": tmp_path / "." / "images" / "one.jpg"}, {"--images": images})
    with pytest.raises(InputFileError, match="inside the input folder"):
        check_outputs({"--json": images / "new.json"}, {"--images": images})
    check_outputs({"--json": tmp_path / "new.json"}, {"--images": images})
    store = tmp_path / "store"
    store.mkdir()
    (store / "sweep.sqlite").write_bytes(b"db")
    for name in ("sweep.sqlite", "sweep.sqlite-wal", "tables.json"):
        with pytest.raises(InputFileError, match="writes into the results store STORE"):
            check_outputs({"--prediction": store / name}, stores={"STORE": store})
    check_outputs({"--out (report.html)": store / "report" / "report.html"},
                  stores={"STORE": store})
    (tmp_path / "hue_de3").mkdir()
    with pytest.raises(InputFileError, match=r"--out \(hue_de3\) would write into the input "
                                             r"folder --images"):
        check_output_folders({"--out (hue_de3)": tmp_path / "hue_de3"},
                             {"--images": tmp_path / "store" / ".." / "hue_de3"})
    check_output_folders({"--out (hue_de3)": tmp_path / "x" / "hue_de3"}, {"--images": images})


def test_write_errors_leave_no_partial_file(tmp_path: Path, monkeypatch) -> None:
    """A full disk while writing: InputFileError naming the output, the temporary file gone,
    an earlier file of the same name as it was; other OSErrors go on as they are."""
    import errno

    target = tmp_path / "out.json"
    target.write_text("earlier")

    def full(self, *a, **k):  # noqa: ANN001, ANN002, ANN003
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(InputFileError, match=r"out.json: cannot write the output: No space "
                                             r"left on device"):
        write_text_atomic(target, "new")
    monkeypatch.undo()
    assert target.read_text() == "earlier"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]
    with pytest.raises(InputFileError, match="Read-only file system"):
        with atomic_output(tmp_path / "x.txt"):
            raise OSError(errno.EROFS, "Read-only file system")
    with pytest.raises(OSError, match="something else"):
        with atomic_output(tmp_path / "y.txt"):
            raise OSError(errno.EBADF, "something else")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_undecodable_file_names_print() -> None:
    from fidelity.core.fileio import display_path, printable

    assert display_path(b"chart\xff.png") == "chart\\xff.png"
    assert printable("chart\udcff.png") == "chart\\xff.png"
    assert printable("\ud800 ok é") == "\\ud800 ok é"
    assert printable("plain ΔE") == "plain ΔE"


def test_a_cached_reader_reads_a_file_again_only_when_it_changes(tmp_path, monkeypatch):
    from fidelity.core.fileio import cached_while_unchanged

    reads = []

    @cached_while_unchanged(maxsize=4)
    def read(path):
        reads.append(path)
        text = path.read_text()
        if text == "broken":
            raise ValueError(text)
        return [text]

    f = tmp_path / "a.json"
    f.write_text("one")
    first = read(f)
    assert read(f) is first and len(reads) == 1  # unchanged: the same result, not read again
    f.write_text("three")
    assert read(f) == ["three"] and len(reads) == 2  # changed: read again
    monkeypatch.chdir(tmp_path)
    assert read(Path("a.json")) == ["three"] and len(reads) == 3  # another spelling: its own
    f.write_text("broken")
    for _ in range(2):  # an error is not kept: a broken file is read each time
        with pytest.raises(ValueError):
            read(f)
    assert len(reads) == 5


# ------------------------------------------------------------------ outputs through links and
# special files (issue 57: a link was replaced by a regular file, /dev/stdout too)

def _no_temporaries(*folders: Path) -> None:
    for folder in folders:
        assert not [p.name for p in folder.iterdir() if p.name.endswith(".tmp") or
                    ".tmp." in p.name], folder


def test_a_link_to_a_file_writes_the_file_and_stays_a_link(tmp_path: Path) -> None:
    target = tmp_path / "target.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to("target.json")
    assert write_text_atomic(link, "new") == link
    assert link.is_symlink() and os.readlink(link) == "target.json"
    assert target.read_text() == "new" and not target.is_symlink()
    _no_temporaries(tmp_path)


def test_a_link_to_a_link_writes_the_last_target(tmp_path: Path) -> None:
    (tmp_path / "c.txt").write_text("old")
    (tmp_path / "b.txt").symlink_to(tmp_path / "c.txt")  # absolute
    (tmp_path / "a.txt").symlink_to("b.txt")  # relative
    write_bytes_atomic(tmp_path / "a.txt", b"new")
    assert [os.readlink(tmp_path / n) for n in ("a.txt", "b.txt")] == [
        "b.txt", str(tmp_path / "c.txt")]
    assert (tmp_path / "c.txt").read_bytes() == b"new"
    _no_temporaries(tmp_path)


def test_a_dangling_link_creates_its_target(tmp_path: Path) -> None:
    link = tmp_path / "report.json"
    link.symlink_to(Path("reports") / "day" / "report.json")  # the folders are not there yet
    write_json_atomic(link, {"a": 1})
    assert link.is_symlink()
    made = tmp_path / "reports" / "day" / "report.json"
    assert made.is_file() and not made.is_symlink() and made.read_text() == '{\n  "a": 1\n}\n'


def test_a_relative_link_in_another_folder_writes_atomically_beside_its_target(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The temporary file is made in the target's folder (a rename cannot cross file systems,
    and the link's folder may be read-only), whatever the working folder is."""
    (tmp_path / "out").mkdir()
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "r.txt").write_text("old")
    (tmp_path / "out" / "r.txt").symlink_to(Path("..") / "data" / "r.txt")
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    with atomic_output(Path("..") / "out" / "r.txt") as tmp:
        assert tmp.parent == (tmp_path / "data").resolve()
        tmp.write_text("new")
    assert (tmp_path / "out" / "r.txt").is_symlink()
    assert (tmp_path / "data" / "r.txt").read_text() == "new"
    _no_temporaries(tmp_path / "out", tmp_path / "data", tmp_path / "elsewhere")


def test_a_link_to_an_input_is_refused_and_a_loop_is_an_input_error(tmp_path: Path) -> None:
    src = tmp_path / "in.json"
    src.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(src)
    with pytest.raises(InputFileError, match="link.json: refusing to write over an input"), \
            atomic_output(link, protect=[src]):
        pass
    with pytest.raises(InputFileError, match="refusing"), atomic_output(src, protect=[link]):
        pass
    assert src.read_text() == "{}" and link.is_symlink()
    (tmp_path / "x").symlink_to("y")
    (tmp_path / "y").symlink_to("x")
    with pytest.raises(InputFileError, match="x: cannot write: too many levels of symbolic"):
        write_text_atomic(tmp_path / "x", "z")
    assert (tmp_path / "x").is_symlink() and (tmp_path / "y").is_symlink()


def test_a_fifo_is_written_as_a_stream(tmp_path: Path) -> None:
    import stat
    import threading

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    link = tmp_path / "link.xml"
    link.symlink_to(fifo)
    got: list[bytes] = []
    for out in (fifo, link):
        reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
        reader.start()
        write_text_atomic(out, "<a>ΔE</a>\n")
        reader.join(timeout=10)
        assert not reader.is_alive()
    assert got == ["<a>ΔE</a>\n".encode()] * 2
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and link.is_symlink()
    _no_temporaries(tmp_path)


def test_a_character_device_stays_one(tmp_path: Path) -> None:
    import stat

    from fidelity.core.fileio import destination, is_stream

    assert destination(os.devnull).kind == "stream"  # before anything is written to it
    link = tmp_path / "null.json"
    link.symlink_to(os.devnull)
    assert destination(link) == ("stream", Path(os.devnull), None) and is_stream(link)
    write_json_atomic(link, {"a": 1})
    write_text_atomic(os.devnull, "x")
    assert stat.S_ISCHR(os.lstat(os.devnull).st_mode) and link.is_symlink()
    # a special file may take two outputs; a regular file may not
    check_outputs({"--json": os.devnull, "--junit": link})
    with pytest.raises(InputFileError, match="named by both"):
        check_outputs({"--json": tmp_path / "r", "--junit": tmp_path / "r"})


_WRITE_STDOUT = ("import sys; from fidelity.core.fileio import write_text_atomic; "
                 "print('printed first'); write_text_atomic(sys.argv[1], 'the output\\n'); "
                 "print('printed after')")


@pytest.mark.parametrize("name", ["/dev/stdout", "/dev/fd/1", "/proc/self/fd/1", "link"])
def test_dev_stdout_writes_this_process_standard_output(name: str, tmp_path: Path) -> None:
    """To a pipe, and to a regular file the shell opened (``> out.txt``): the output lands in
    order between what the process prints, in the file the shell made (never a new file
    renamed over it)."""
    import subprocess
    import sys

    from fidelity.core.fileio import destination

    if not Path(name if name != "link" else "/dev/stdout").exists():
        pytest.skip(f"{name}: not on this system")
    if name == "link":
        (tmp_path / "link").symlink_to("/dev/stdout")
        name = str(tmp_path / "link")
    # first, here: a process that replaced /dev/stdout (as root) would break the machine's
    assert destination(name).kind == "descriptor"
    piped = subprocess.run([sys.executable, "-c", _WRITE_STDOUT, name], capture_output=True,
                           text=True, check=True, timeout=60)
    assert piped.stdout == "printed first\nthe output\nprinted after\n", piped.stderr
    out = tmp_path / "out.txt"
    with open(out, "w") as fh:
        inode = os.fstat(fh.fileno()).st_ino
        subprocess.run([sys.executable, "-c", _WRITE_STDOUT, name], stdout=fh, check=True,
                       timeout=60)
    assert out.read_text() == "printed first\nthe output\nprinted after\n"
    assert out.stat().st_ino == inode


def test_the_cli_writes_through_a_link_and_to_dev_stdout(tmp_path: Path) -> None:
    """``--json link.json`` (link.json -> reports/target.json): the link stays, the target is
    the report; ``--json /dev/stdout`` prints it (a process, as a shell runs it)."""
    import json
    import subprocess
    import sys

    from click.testing import CliRunner

    from fidelity.cli import main
    from fidelity.core.fileio import destination

    (tmp_path / "reports").mkdir()
    target = tmp_path / "reports" / "target.json"
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(Path("reports") / "target.json")
    r = CliRunner().invoke(main, ["predict", "--delta-e", "3", "--json", str(link)])
    assert r.exit_code == 0, r.output
    assert f"wrote {link}" in r.stdout
    assert link.is_symlink() and os.readlink(link) == str(Path("reports") / "target.json")
    assert json.loads(target.read_text())["delta_e"] == 3.0
    _no_temporaries(tmp_path, tmp_path / "reports")
    assert destination("/dev/stdout").kind == "descriptor"  # never replaced, even as root
    p = subprocess.run([sys.executable, "-m", "fidelity", "predict", "--delta-e", "3", "-q",
                        "--json", "/dev/stdout"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["delta_e"] == 3.0
