"""No test unit enters a default: each calibration reads its split's tuning units only.

Two kinds of evidence: the derivations are instrumented (which seeds, robots, sites they read), and on the shared
MRCLAM files a held-out robot's data is perturbed and its fold's noise stays the same to the last bit while another
fold's moves.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.datasets import splits as sp
from locbench.datasets.recorded import mrclam, mrclam_noise, radish
from locbench.datasets.recorded.mrclam import MrclamDataset, load_mrclam
from locbench.datasets.synthetic import odometry_calibration as oc

needs_mrclam = pytest.mark.skipif(
    MrclamDataset.data_unavailable() is not None, reason=str(MrclamDataset.data_unavailable())
)


# --- the synthetic calibrations read tuning seeds only ------------------------------------------------------------


def test_room_calibration_reads_tuning_seeds_only(monkeypatch: pytest.MonkeyPatch) -> None:
    read: set[int] = set()
    real_rng = oc.dataset_rng

    def spy_rng(name: str, seed: int) -> np.random.Generator:
        read.add(seed)
        return real_rng(name, seed)

    def fake_errors(*args: Any, seeds: Any = (), **kw: Any) -> np.ndarray:
        read.update(seeds)
        return np.full(5, 0.1)

    monkeypatch.setattr(oc, "dataset_rng", spy_rng)
    monkeypatch.setattr(oc, "room_dead_reckoning_errors", fake_errors)
    monkeypatch.setattr(oc, "room_motion", lambda: type("M", (), {"n_steps": 4})())
    oc.calibrate_room_odometry()
    assert read == set(sp.CALIBRATION_SEEDS)
    assert not read & set(sp.test_seeds(sp.CALIBRATION_SEED_COUNT))


def test_lap_calibration_reads_tuning_seeds_only(monkeypatch: pytest.MonkeyPatch) -> None:
    read: set[int] = set()

    def fake(scale: float, seeds: Any = (), dataset_name: str = "lap") -> np.ndarray:
        read.update(seeds)
        return np.full(len(seeds), 0.1 + scale)

    monkeypatch.setattr(oc, "lap_dead_reckoning_final_errors", fake)
    oc.calibrate_lap_odometry(target_m=0.3)
    assert read == set(sp.CALIBRATION_SEEDS)


def test_a_calibration_refuses_a_split_whose_tuning_side_holds_a_test_seed() -> None:
    # a split is checked where it is made: a seed cannot be on both sides
    with pytest.raises(ConfigError):
        sp.Split("bad", (0, 1000), (0,), "r")


# --- the Radish encoder-error fit reads tuning sites only --------------------------------------------------------


def _spy_radish(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    read: list[str] = []

    def fake_locate(spec: Any, root: Any = None) -> Path:
        read.append(spec.relpath.rsplit("/", 1)[-1].removesuffix(radish.SUFFIX))
        return Path(spec.relpath)

    monkeypatch.setattr(radish, "locate", fake_locate)
    monkeypatch.setattr(radish, "read_corrected", lambda path: path)
    monkeypatch.setattr(radish, "paired_raw", lambda site, cl, root: object())
    monkeypatch.setattr(radish, "paired_poses", lambda cl, pairing: (np.zeros((2, 3)), np.zeros((2, 3))))
    monkeypatch.setattr(radish, "fit_encoder_error", lambda pairs: radish.EncoderError(0.0, 0.0, 0.0, len(pairs)))
    return read


def test_radish_fit_reads_tuning_sites_only(monkeypatch: pytest.MonkeyPatch) -> None:
    read = _spy_radish(monkeypatch)
    radish.fit_paired_sites()
    assert read and set(read) <= set(sp.RADISH_SPLIT.tuning)
    assert not set(read) & set(sp.RADISH_SPLIT.test)
    # were aces a test site, the fit would not read it
    read.clear()
    other = sp.radish_split(fixed=("intel", "freiburg-079"))
    assert other.role("aces") == "test"
    radish.fit_paired_sites(split=other)
    assert "aces" not in read and read


def test_radish_fit_without_a_paired_tuning_site_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    _spy_radish(monkeypatch)
    with pytest.raises(ConfigError, match="no tuning site has raw odometry"):
        radish.fit_paired_sites(split=sp.Split("none", ("acapulco",), ("intel",), "r"))


# --- MRCLAM: each robot's noise comes from its fold's other robots ----------------------------------------------


def test_each_robot_is_given_its_own_folds_noise(tmp_path: Path) -> None:
    from test_recorded_mrclam import _small_folder

    ds = load_mrclam(_small_folder(tmp_path), 1)
    assert ds.sensors == mrclam.nominal_sensors(1)
    assert ds.sensors.landmark_sigma_range_m == mrclam.FOLD_NOISE[1]["landmark_sigma_range_m"]
    assert set(mrclam.FOLD_NOISE) == set(mrclam.ROBOTS)
    assert "robot 1 held out" in ds.metadata["nominal_noise"]


def test_mrclam_derivation_reads_the_folds_tuning_robots_only(monkeypatch: pytest.MonkeyPatch) -> None:
    read: list[int] = []
    rng = np.random.default_rng(0)

    def spy(folder: Path, robot: int, window_s: float) -> tuple[Any, ...]:
        read.append(robot)
        n = 50
        errors = (rng.normal(size=n) for _ in range(3))
        w = mrclam_noise._Windows(*errors, rng.uniform(0, 0.1, n), rng.uniform(0, 0.1, n))
        return rng.normal(size=n), rng.normal(size=n), w, 0.01, 1.0

    monkeypatch.setattr(mrclam_noise, "_robot_residuals", spy)
    for held_out in mrclam.ROBOTS:
        read.clear()
        mrclam_noise.derive_fold_noise("/unused", held_out)
        assert sorted(read) == [r for r in mrclam.ROBOTS if r != held_out]


def _perturbed_copy(src: Path, dst: Path, robot: int) -> Path:
    """Dataset 6 with ``robot``'s odometry 30 % fast and its ranges 0.5 m long; the other files linked."""
    dst.mkdir()
    for f in src.iterdir():
        (dst / f.name).symlink_to(f)
    for name, column, change in ((f"Robot{robot}_Odometry.dat", 1, 1.3), (f"Robot{robot}_Measurement.dat", 2, 0.5)):
        (dst / name).unlink()
        out = []
        for line in (src / name).read_text().splitlines():
            parts = line.split()
            if line.lstrip().startswith("#") or len(parts) < 3:
                out.append(line)
                continue
            v = float(parts[column])
            parts[column] = f"{v * change:.6f}" if column == 1 else f"{v + change:.6f}"
            out.append("\t".join(parts))
        (dst / name).write_text("\n".join(out) + "\n")
    return dst


@pytest.mark.recorded
@pytest.mark.slow
@needs_mrclam
def test_perturbing_a_held_out_robot_leaves_its_folds_noise_unchanged(tmp_path: Path) -> None:
    src = Path(os.environ["LOCBENCH_DATA"]) / "utias_mrclam" / "MRCLAM_Dataset6"
    held_out = 5
    changed = _perturbed_copy(src, tmp_path / "MRCLAM_Dataset6", held_out)
    before = mrclam_noise.derive_fold_noise(src, held_out)
    after = mrclam_noise.derive_fold_noise(changed, held_out)
    assert after == before  # to the last bit: robot 5's data is not read for its own noise
    # the perturbation is large enough to move a fold that does read robot 5
    other_before = mrclam_noise.derive_fold_noise(src, 1)
    other_after = mrclam_noise.derive_fold_noise(changed, 1)
    assert other_after["twist_sigma_v_mps"] > 1.1 * other_before["twist_sigma_v_mps"]
    assert other_after["landmark_sigma_range_m"] > 1.1 * other_before["landmark_sigma_range_m"]
