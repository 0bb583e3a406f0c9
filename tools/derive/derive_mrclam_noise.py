"""Print MRCLAM's nominal noise of every leave-one-robot-out fold as derived from one dataset folder.

Usage: python tools/derive/derive_mrclam_noise.py FOLDER   (an MRCLAM dataset folder, e.g. .../MRCLAM_Dataset6)

The procedure is :func:`locbench.datasets.recorded.mrclam_noise.derive_fold_noise` (the module docstring of
``mrclam_noise`` says how): fold r pools the four robots other than r (``locbench.datasets.splits.mrclam_fold``).
The frozen ``FOLD_NOISE`` of ``locbench.datasets.recorded.mrclam`` came from Dataset 6.
"""

from __future__ import annotations

import json
import sys

from locbench.datasets.recorded.mrclam_noise import derive_fold_noise
from locbench.datasets.splits import MRCLAM_ROBOTS

if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__.split("\n\n")[1])
    print(json.dumps({f"fold {r}": derive_fold_noise(sys.argv[1], r) for r in MRCLAM_ROBOTS}, indent=2))
