"""Print the landmark_geometry detector's error against the truth, the basis of its nominal landmark noise.

Usage: python tools/derive/landmark_detection_stats.py

Builds every realisation of :func:`locbench.datasets.synthetic.detection_error.detection_cases` and prints
:func:`~locbench.datasets.synthetic.detection_error.detection_error_stats` of them (the module says what the
nominal noise takes from it).
"""

from __future__ import annotations

from locbench.datasets.synthetic.detection_error import detection_cases, detection_error_stats
from locbench.registry import make_dataset

if __name__ == "__main__":
    for k, v in detection_error_stats(make_dataset(name, seed) for name, seed in detection_cases()).items():
        print(f"{k}: {v!r}")
