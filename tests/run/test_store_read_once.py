"""A stored npz is read once: its members' bytes give the checksum and then the arrays, as ``numpy.load`` gives them."""

from __future__ import annotations

import hashlib
import zipfile
from pathlib import Path

import numpy as np
import pytest

from locbench.evaluate.records import RunRecord
from locbench.run import store as store_mod
from locbench.run.store import Store


def _record() -> RunRecord:
    n = 5
    meta = {"dataset": "room", "filter": "odometry", "seed": 3, "run_key": "k", "status": "ok"}
    rng = np.random.default_rng(0)
    return RunRecord(
        meta,
        np.arange(n, dtype=float),
        rng.normal(size=(n, 3)),
        np.tile(np.eye(3), (n, 1, 1)),
        np.zeros(n, np.int8),
        np.arange(n, dtype=np.int64),
        {"nis": rng.normal(size=n)},
        {"smoothed": rng.normal(size=(n, 3))},
        {"spread": rng.normal(size=n)},
    )


def _digest_by_streaming(path: Path) -> str:
    """The checksum as a second pass over the zip computes it: every member streamed in name order."""
    h = hashlib.sha256()
    with zipfile.ZipFile(path) as z:
        for name in sorted(z.namelist()):
            h.update(name.encode() + b"\0")
            h.update(z.read(name))
    return h.hexdigest()


def test_arrays_equal_numpy_load(tmp_path: Path) -> None:
    st = Store(tmp_path)
    folder = st.write_run(_record())
    npz = folder / "estimates.npz"
    meta, arrays = store_mod._load_verified(npz, folder / "meta.json", store_mod.run_problem, required_record=True)
    with np.load(npz, allow_pickle=False) as z:
        want = {k: z[k] for k in z.files}
    assert list(arrays) == list(want)
    for k, v in want.items():
        assert arrays[k].dtype == v.dtype and arrays[k].shape == v.shape, k
        assert arrays[k].tobytes() == v.tobytes(), k
        assert arrays[k].flags.writeable, k
    assert store_mod.npz_digest(npz) == _digest_by_streaming(npz) == meta["files"]["estimates.npz"]


def test_members_not_in_npy_format_and_npy_names(tmp_path: Path) -> None:
    """A member without the ``.npy`` suffix keeps its name; one not in ``.npy`` format gives its bytes."""
    path = tmp_path / "odd.npz"
    np.savez(path, a=np.arange(3.0))
    with zipfile.ZipFile(path, "a") as z:
        z.writestr("raw", b"not an array")
    names, data = store_mod._npz_members(path)
    got = store_mod._members_arrays(names, data)
    with np.load(path, allow_pickle=False) as z:
        want = {k: z[k] for k in z.files}
    assert list(got) == list(want) == ["a", "raw"]
    assert np.array_equal(got["a"], want["a"]) and got["raw"] == want["raw"] == b"not an array"


def test_an_altered_member_is_refused(tmp_path: Path) -> None:
    st = Store(tmp_path)
    folder = st.write_run(_record())
    npz = folder / "estimates.npz"
    with np.load(npz) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["mean"] = arrays["mean"] + 1.0
    np.savez(npz, **arrays)
    with pytest.raises(store_mod.StaleRecord, match="sha256 does not match"):
        st.read_run(folder)


_ARRAYS = {
    "f8_2d": np.arange(12.0).reshape(4, 3),
    "fortran": np.asfortranarray(np.arange(24, dtype=np.float32).reshape(2, 3, 4)),
    "scalar": np.array(2.5),
    "text": np.array("a" * 64),
    "names": np.array(["ate_m", "nees_mean"], dtype=np.str_),
    "flags": np.array([True, False, True]),
    "i8_big_endian": np.arange(5, dtype=">i8"),
    "empty": np.zeros((0, 3)),
    "u1": np.arange(7, dtype=np.uint8),
    "c16": np.array([1 + 2j, 3 - 4j]),
    "stamps": np.array([0, 1, 2], dtype="datetime64[ns]"),
    "record": np.zeros(2, dtype=[("x", "<f8"), ("n", "<i4")]),
}


@pytest.mark.parametrize("save", [np.savez, np.savez_compressed], ids=["stored", "compressed"])
def test_every_dtype_and_order_reads_as_numpy_load(tmp_path: Path, save: object) -> None:
    """The header parsed here (plain dtypes, both orders, 0-d and empty shapes) and the ones left to numpy (a
    structured dtype, a compressed member) give numpy.load's arrays, writable."""
    path = tmp_path / "many.npz"
    save(path, **_ARRAYS)  # type: ignore[operator]
    got = store_mod._members_arrays(*store_mod._npz_members(path))
    with np.load(path, allow_pickle=False) as z:
        want = {k: z[k] for k in z.files}
    assert list(got) == list(want)
    for k, v in want.items():
        assert got[k].dtype == v.dtype and got[k].shape == v.shape, k
        assert np.array_equal(got[k], v), k
        assert got[k].flags.f_contiguous == v.flags.f_contiguous, k
        assert got[k].flags.writeable, k


def test_a_pickled_member_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "objects.npz"
    np.savez(path, o=np.array([{"a": 1}, None], dtype=object))
    with pytest.raises(ValueError, match="allow_pickle"):
        store_mod._members_arrays(*store_mod._npz_members(path))


def _flip_last_byte_of(path: Path, member: str) -> None:
    with zipfile.ZipFile(path) as z:
        info = z.getinfo(member)
    raw = bytearray(path.read_bytes())
    at = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + info.compress_size - 1
    raw[at] ^= 0xFF
    path.write_bytes(bytes(raw))


def test_a_damaged_member_fails_its_crc_as_zipfile_says(tmp_path: Path) -> None:
    path = tmp_path / "a.npz"
    np.savez(path, a=np.arange(100.0))
    _flip_last_byte_of(path, "a.npy")
    with pytest.raises(zipfile.BadZipFile), zipfile.ZipFile(path) as z:
        z.read("a.npy")
    with pytest.raises(zipfile.BadZipFile, match="CRC-32"):
        store_mod._npz_members(path)


def test_a_cut_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "a.npz"
    np.savez(path, a=np.arange(100.0))
    path.write_bytes(path.read_bytes()[:-300])
    with pytest.raises(zipfile.BadZipFile):
        store_mod._npz_members(path)


def test_a_short_array_is_refused(tmp_path: Path) -> None:
    """A header that promises more elements than its member holds is an error, not a shorter array."""
    buf = np.lib.format.MAGIC_PREFIX + b"\x01\x00"
    header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (4,), }"
    header += b" " * (-(len(buf) + 2 + len(header) + 1) % 64) + b"\n"
    raw = buf + len(header).to_bytes(2, "little") + header + np.arange(3.0).tobytes()
    with pytest.raises(ValueError, match="EOF"):
        store_mod._npy_array(raw)


@pytest.mark.parametrize("key", [k for k in _ARRAYS if k != "record"])
def test_numpy_writes_the_header_read_without_numpy(key: str) -> None:
    """The plain dtypes are parsed here, not by numpy's literal_eval: the header numpy writes is the one expected."""
    import io

    out = io.BytesIO()
    np.save(out, _ARRAYS[key])
    raw = out.getvalue()
    end = 10 + int.from_bytes(raw[8:10], "little")
    assert raw[6:8] == b"\x01\x00"
    assert store_mod._NPY_HEADER.fullmatch(raw[10:end].decode("latin1")) is not None


def test_a_damaged_member_of_a_run_is_refused_by_its_sha256(tmp_path: Path) -> None:
    """Where the record's sha256 is checked, the CRC-32 is not needed: a damaged member is still refused."""
    st = Store(tmp_path)
    folder = st.write_run(_record())
    _flip_last_byte_of(folder / "estimates.npz", "mean.npy")
    with pytest.raises(store_mod.StaleRecord, match="sha256 does not match"):
        st.read_run(folder)
