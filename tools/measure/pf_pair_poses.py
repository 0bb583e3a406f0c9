"""How far from the truth are the poses `pf` injects from sighting pairs? (docs/pf_consistency_kidnap.md, 2 (f))

Usage: ``python tools/measure/pf_pair_poses.py 'pf[augmented=true,inject=sensor,inject_pairs=true]' office 8``.
Runs the filter as the runner does (its seed stream) and prints, for every injection from a pair, the
median distance of the injected poses to the true position and the odometry since the previous event.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from locbench.core.seeding import filter_rng
from locbench.filters.pf import ParticleFilter
from locbench.registry import make_dataset, resolve_filter
from locbench.run.runner import run_filter


def main(spec: str, dataset: str, seed: int) -> None:
    records: list[tuple[float, np.ndarray, np.ndarray]] = []
    original = ParticleFilter._injected_poses

    def recording(self: Any, kind: Any, data: Any, count: int, pair: Any = None) -> Any:
        out = original(self, kind, data, count, pair)
        if pair is not None:
            records.append((float(self._t), np.array(out, copy=True), np.array(pair[1], copy=True)))
        return out

    ParticleFilter._injected_poses = recording  # type: ignore[method-assign]
    ds = make_dataset(dataset, seed)
    fr = resolve_filter(spec)
    run_filter(ParticleFilter(fr.params), ds, filter_rng(fr.name, ds.name, seed))
    gt = ds.ground_truth
    for t, poses, delta in records:
        i = min(int(np.searchsorted(gt.t, t)), len(gt.t) - 1)
        d = np.hypot(poses[:, 0] - gt.xy[i, 0], poses[:, 1] - gt.xy[i, 1])
        print(
            f"t={t:.1f} s n={len(poses)}: median {100 * np.median(d):.1f} cm from the truth, "
            f"{np.mean(d < 0.1):.2f} within 10 cm, {np.mean(d > 1):.2f} beyond 1 m; odometry since the previous "
            f"event {np.hypot(delta[0], delta[1]):.2f} m, {np.degrees(delta[2]):.0f} deg"
        )


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
