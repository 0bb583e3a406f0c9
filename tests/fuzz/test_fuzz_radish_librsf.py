"""Property-based fuzzing of the Radish corrected-log and libRSF loaders, as
tests/fuzz/test_fuzz_loaders.py does for the others: any mutation of a small valid file is a clean one-line locbench
error naming the file, or a dataset that passes the contract, under the same address-space limit."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from test_fuzz_loaders import _fresh_dir, base, memory_limit, outcome_is_clean, text_mutation
from test_recorded_librsf import write_sim, write_uwb
from test_recorded_radish import _path, corrected_text, write_raw, write_site

from locbench.datasets.recorded.librsf import load_librsf
from locbench.datasets.recorded.radish import load_radish

__all__ = ["base", "memory_limit"]  # the fixtures, used by name

CORRECTED = corrected_text(_path(6)).encode("ascii")


@given(data=st.data())
def test_corrected_log_mutations(base: Path, data: st.DataObject) -> None:
    root = _fresh_dir(base)
    write_site(root, "box", data.draw(text_mutation(CORRECTED)))
    outcome_is_clean(lambda: load_radish("box", root, np.random.default_rng(0)), [str(root / "radish_corrected")])


@given(data=st.data())
def test_corrected_gzip_bytes_mutations(base: Path, data: st.DataObject) -> None:
    """Truncated or flipped compressed bytes: a clean gzip error, never a traceback."""
    root = _fresh_dir(base)
    path = write_site(root, "box", CORRECTED)
    raw = bytearray(path.read_bytes())
    if data.draw(st.booleans()):
        raw = raw[: data.draw(st.integers(0, len(raw)))]
    else:
        k = data.draw(st.integers(0, len(raw) - 1))
        raw[k] ^= data.draw(st.integers(1, 255))
    path.write_bytes(bytes(raw))
    outcome_is_clean(lambda: load_radish("box", root), [str(path)])


@given(data=st.data())
def test_raw_log_mutations(base: Path, data: st.DataObject) -> None:
    root = _fresh_dir(base)
    poses = _path(6)
    write_site(root, "aces", corrected_text(poses, t0=21.0))
    raw = write_raw(root, "aces", poses, t0=976052857.0)
    raw.write_bytes(data.draw(text_mutation(raw.read_bytes())))
    outcome_is_clean(lambda: load_radish("aces", root, verify=False), [str(root)])


@given(data=st.data(), which=st.sampled_from(["input", "gt"]))
def test_librsf_simulated_mutations(base: Path, data: st.DataObject, which: str) -> None:
    root = _fresh_dir(base)
    path = write_sim(root, n=6)
    if which == "gt":
        path = path.parent / "M3500_GT.txt"
    path.write_bytes(data.draw(text_mutation(path.read_bytes())))
    outcome_is_clean(lambda: load_librsf("m3500", "skewed", root, verify=False), [str(path.parent)])


@given(data=st.data(), which=st.sampled_from(["input", "gt"]))
def test_librsf_uwb_mutations(base: Path, data: st.DataObject, which: str) -> None:
    root = _fresh_dir(base)
    path = write_uwb(root, n=8)
    if which == "gt":
        path = path.parent / "Indoor_UWB_GT.txt"
    path.write_bytes(data.draw(text_mutation(path.read_bytes())))
    outcome_is_clean(lambda: load_librsf("indoor_uwb", "", root, verify=False), [str(path.parent)])


def test_gzip_of_a_valid_log_is_valid(base: Path) -> None:
    root = _fresh_dir(base)
    write_site(root, "box", CORRECTED)
    load_radish("box", root).check()
    assert gzip.decompress((root / "radish_corrected" / "box-corrected.log.gz").read_bytes()) == CORRECTED
