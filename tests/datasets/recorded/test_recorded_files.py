"""Recorded-data plumbing: locating, verifying and downloading files, table parsing errors, relation error."""

from __future__ import annotations

import bz2
import functools
import hashlib
import http.server
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from locbench.core.errors import ConfigError, DataNotFound
from locbench.core.geometry import between, compose
from locbench.datasets.recorded.files import (
    MissingDataFile,
    RecordedDataError,
    RemoteFile,
    locate,
    read_table,
    verify_sha256,
)
from locbench.evaluate.metrics import relation_errors

COLS = ("time [s]", "x [m]", "y [m]")


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_bytes(text.encode())
    return p


def test_read_table_skips_comments_and_crlf(tmp_path: Path) -> None:
    p = _write(tmp_path, "ok.dat", "# header\r\n1.0 \t 2.0  3.0 \r\n\r\n2.0\t4.0\t5.0\r\n")
    t = read_table(p, COLS)
    np.testing.assert_array_equal(t.rows, [[1.0, 2.0, 3.0], [2.0, 4.0, 5.0]])
    np.testing.assert_array_equal(t.lines, [2, 4])


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("1 2 3\n4 5 6\n7 8", 3, "truncated line"),
        ("1 2 3\n4 5 6 7\n", 2, "wrong column count"),
        ("1 2 3\n4 x 6\n", 2, "expected a number"),
        ("1 2 3\n4 nan 6\n", 2, "non-finite"),
    ],
)
def test_read_table_errors_name_file_and_line(tmp_path: Path, text: str, line: int, words: str) -> None:
    p = _write(tmp_path, "bad.dat", "# c\n" + text)
    with pytest.raises(RecordedDataError, match=words) as info:
        read_table(p, COLS)
    assert info.value.line == line + 1
    assert str(info.value).startswith(f"{p}:{line + 1}: ")
    assert isinstance(info.value, ConfigError)


def test_time_going_backwards_names_the_line(tmp_path: Path) -> None:
    p = _write(tmp_path, "back.dat", "1 0 0\n2 0 0\n1.5 0 0\n")
    t = read_table(p, COLS)
    with pytest.raises(RecordedDataError, match=r"back.dat:3: time goes backwards"):
        t.check_time_non_decreasing()


def test_integer_columns(tmp_path: Path) -> None:
    p = _write(tmp_path, "ids.dat", "1 5\n2 5.5\n")
    with pytest.raises(RecordedDataError, match=r"ids.dat:2: field 2 \(id\) is '5.5', expected an integer"):
        read_table(p, ("t", "id"), integer_columns=(1,))


def test_locate_prefers_the_data_root_and_verifies(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "data"
    (root / "set").mkdir(parents=True)
    f = root / "set" / "a.dat"
    f.write_bytes(b"1 2 3\n")
    digest = hashlib.sha256(b"1 2 3\n").hexdigest()
    monkeypatch.setenv("LOCBENCH_DATA", str(root))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    assert locate(RemoteFile("set/a.dat", digest)) == f
    f.write_bytes(b"1 2 4\n")  # an edited copy
    with pytest.raises(RecordedDataError, match="checksum mismatch"):
        locate(RemoteFile("set/a.dat", digest))


def test_missing_file_says_where_it_looked(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LOCBENCH_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    with pytest.raises(MissingDataFile, match=r"missing file .*no official download") as info:
        locate(RemoteFile("set/b.dat"))
    assert isinstance(info.value, DataNotFound)
    assert "set/b.dat" in str(info.value)


@pytest.fixture
def http_folder(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """A local HTTP server over a folder (downloads without the internet)."""
    served = tmp_path / "served"
    served.mkdir()

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, format: str, *args: object) -> None:
            pass

    handler = functools.partial(Quiet, directory=str(served))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", served
    finally:
        server.shutdown()
        server.server_close()


def test_download_is_verified_and_decompressed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, http_folder: tuple[str, Path]
) -> None:
    url, served = http_folder
    payload = b"ODOM 0 0 0\n" * 50
    (served / "log.clf.bz2").write_bytes(bz2.compress(payload))
    monkeypatch.delenv("LOCBENCH_DATA", raising=False)
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    spec = RemoteFile(
        "set/log.clf",
        sha256=hashlib.sha256(payload).hexdigest(),
        url=f"{url}/log.clf.bz2",
        download_sha256=hashlib.sha256((served / "log.clf.bz2").read_bytes()).hexdigest(),
        decompress="bz2",
    )
    with pytest.raises(MissingDataFile):
        locate(spec)  # no download unless asked
    path = locate(spec, download=True)
    assert path.read_bytes() == payload
    assert locate(spec) == path  # found in the cache afterwards


def test_download_with_wrong_checksum_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, http_folder: tuple[str, Path]
) -> None:
    url, served = http_folder
    (served / "x.dat").write_bytes(b"tampered\n")
    monkeypatch.delenv("LOCBENCH_DATA", raising=False)
    cache = tmp_path / "cache"
    monkeypatch.setenv("LOCBENCH_CACHE", str(cache))
    spec = RemoteFile("set/x.dat", sha256=hashlib.sha256(b"original\n").hexdigest(), url=f"{url}/x.dat")
    with pytest.raises(RecordedDataError, match=r"download from .* failed|checksum mismatch"):
        locate(spec, download=True)
    assert not (cache / "set" / "x.dat").exists()


def test_verify_sha256_accepts_the_right_digest(tmp_path: Path) -> None:
    p = _write(tmp_path, "f", "abc")
    verify_sha256(p, hashlib.sha256(b"abc").hexdigest().upper())


# --- the relation error (Kuemmerle et al. 2009) ----------------------------------------------------


def test_relation_error_is_zero_for_the_reference_and_sees_a_rotation() -> None:
    t = np.arange(6.0)
    poses = np.array([[0, 0, 0], [1, 0, 0.1], [2, 0.2, 0.3], [3, 0.5, 0.2], [4, 1, -0.1], [5, 1, 0]], float)
    t1, t2 = np.array([0.0, 1.0, 2.0]), np.array([2.0, 4.0, 5.0])
    ref = between(poses[[0, 1, 2]], poses[[2, 4, 5]])
    trans, rot = relation_errors(t, poses, t1, t2, ref)
    np.testing.assert_allclose(trans, 0.0, atol=1e-12)
    np.testing.assert_allclose(rot, 0.0, atol=1e-12)
    # a constant world-frame offset of the whole estimate leaves every relation unchanged ...
    shifted = compose(np.array([3.0, -2.0, 0.7]), poses)
    trans, rot = relation_errors(t, shifted, t1, t2, ref)
    np.testing.assert_allclose(trans, 0.0, atol=1e-12)
    # ... a wrong heading increment does not
    bad = poses.copy()
    bad[2:, 2] += 0.05
    trans, rot = relation_errors(t, bad, t1, t2, ref)
    np.testing.assert_allclose(rot, [0.05, 0.05, 0.0], atol=1e-12)  # (2, 5): both poses turned alike


def test_relation_error_leaves_out_relations_outside_the_run() -> None:
    t = np.array([10.0, 11.0, 12.0])
    poses = np.zeros((3, 3))
    trans, _ = relation_errors(t, poses, np.array([9.0, 10.0]), np.array([11.0, 12.0]), np.zeros((2, 3)))
    assert trans.shape == (1,)
