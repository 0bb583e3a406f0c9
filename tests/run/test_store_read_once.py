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
