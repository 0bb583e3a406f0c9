"""Fit the simulated encoder error of the semi-synthetic Radish sites on the three sites with raw odometry.

Run: ``LOCBENCH_DATA=../shared/datasets python tools/derive/fit_radish_odometry.py``. It pairs each corrected scan of
intel, aces and freiburg-079 with the raw scan of identical ranges
(:func:`locbench.datasets.recorded.radish.pair_scans`), and fits the increment model by the pooled method of
moments (:func:`~locbench.datasets.recorded.radish.fit_encoder_error`); the printed constant is
``ENCODER_ERROR`` in ``datasets/recorded/radish.py`` (tests/datasets/recorded/test_recorded_radish.py checks that they
agree).
"""

from __future__ import annotations

import sys

from locbench.datasets.recorded.radish import fit_paired_sites


def main() -> int:
    fit = fit_paired_sites()
    print("ENCODER_ERROR = EncoderError(")
    print(f"    sigma_xy_per_m={fit.sigma_xy_per_m!r},")
    print(f"    sigma_theta_per_m={fit.sigma_theta_per_m!r},")
    print(f"    sigma_theta_per_rad={fit.sigma_theta_per_rad!r},")
    print(f"    pairs={fit.pairs!r},")
    print(")")
    return 0


if __name__ == "__main__":
    sys.exit(main())
