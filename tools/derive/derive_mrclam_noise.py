"""Print MRCLAM's nominal noise as derived from one dataset folder (what the loader's frozen noise came from).

Usage: python tools/derive/derive_mrclam_noise.py FOLDER   (an MRCLAM dataset folder, e.g. .../MRCLAM_Dataset6)

The procedure is :func:`locbench.datasets.recorded.mrclam_noise.derive_nominal_noise` (its module docstring says
how); the frozen constants came from Dataset 6, robots 1-5.
"""

from __future__ import annotations

import json
import sys

from locbench.datasets.recorded.mrclam_noise import derive_nominal_noise

if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__.split("\n\n")[1])
    print(json.dumps(derive_nominal_noise(sys.argv[1]), indent=2))
