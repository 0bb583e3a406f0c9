"""What a recorded dataset's reference is, and the libRSF robustness table (issue 22).

Reference kinds
---------------
Every recorded dataset is scored against its reference trajectory, and the kind of that reference says how far
the scores can be trusted: **motion capture** (Vicon: MRCLAM, Lost in the Woods), **GPS** (CMU Plaza), **survey**
(surveyed marks), **SLAM** (another estimator's output: Intel's GMapping poses, the Radish corrected logs; the map is
built from the same log), **simulation** (the libRSF M3500 / W3500 worlds: exact truth of simulated data) and
**not stated** (the libRSF Labyrinth's ground-truth positions, whose method the dataset does not give). A loader
names its kind in ``metadata["reference_kind"]``; the datasets older than that field are looked up by id in
:data:`KNOWN_KINDS`. The report's recorded section shows one group of tables per kind and says the kind in every
caption; the summary's "recorded median ATE" counts only :data:`INDEPENDENT_KINDS` (measured truth of a recording),
never a SLAM reference or a simulation.

Semi-synthetic data (the Radish sites without raw odometry, ``metadata["odometry"]`` starting with
"semi-synthetic") are marked wherever their name is shown.

Robustness table
----------------
ATE (cm) of each filter on each libRSF world under each range-noise type (heavy-tailed, multimodal, skewed) beside
the generated Gaussian reference of the same world (``noise=gaussian``: the declared 0.25 m^2), and the ratio to that
reference.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from locbench.metrics import METRICS
from locbench.report import tables as tb
from locbench.report.doc import Table

#: The reference kinds, in the order the report groups them.
KINDS = ("motion capture", "GPS", "survey", "not stated", "SLAM", "simulation")
#: Kinds of independent, measured ground truth of a recording: the only ones the summary's recorded median counts.
INDEPENDENT_KINDS = frozenset({"motion capture", "GPS", "survey", "not stated"})
#: The kind of the datasets whose loaders predate ``metadata["reference_kind"]``, by dataset id.
KNOWN_KINDS: dict[str, str] = {
    "mrclam": "motion capture",
    "lost_in_the_woods": "motion capture",
    "plaza": "GPS",
    "intel": "SLAM",
}
#: The noise types of the robustness table, then the Gaussian reference.
NOISE_TYPES = ("heavy-tailed", "multimodal", "skewed")
GAUSSIAN = "gaussian"
WORLDS = ("m3500", "w3500")


def reference_kind(dataset_id: str, metadata: dict[str, Any], truth_label: str) -> str:
    """The kind of a dataset's reference (module docstring); a SLAM truth label is SLAM whatever else is said."""
    if truth_label == "SLAM reference":
        return "SLAM"
    kind = metadata.get("reference_kind")
    if isinstance(kind, str) and kind in KINDS:
        return kind
    return KNOWN_KINDS.get(dataset_id, "not stated")


def semi_synthetic(metadata: dict[str, Any]) -> bool:
    """Whether the dataset's odometry is simulated on top of the recording."""
    return str(metadata.get("odometry", "")).startswith("semi-synthetic")


def kind_caption(kind: str) -> str:
    """The words every table of a group carries."""
    return f"reference: {kind}" + (
        " (another estimator's output, not independent ground truth)" if kind == "SLAM" else ""
    )


def robustness_table(df: pd.DataFrame, filters: list[str]) -> Table | None:
    """ATE per filter per noise type beside the Gaussian reference, for each libRSF world present; None if none is.

    ``df`` holds the stored metric rows (columns dataset, filter, metric, value); dataset names are canonical
    (``librsf[noise=skewed,set=m3500]``).
    """
    cols: list[tuple[str, str, str]] = []  # (world, noise, dataset name)
    names = {str(d) for d in df["dataset"].unique()} if len(df) else set()
    for world in WORLDS:
        for noise in (*NOISE_TYPES, GAUSSIAN):
            name = f"librsf[noise={noise},set={world}]"
            if name in names:
                cols.append((world, noise, name))
    if not cols:
        return None
    scale = METRICS["ate_m"].scale
    ate = df[df["metric"] == "ate_m"]

    def mean(f: str, ds: str) -> float:
        v = ate[(ate["dataset"] == ds) & (ate["filter"] == f)]["value"].to_numpy(dtype=np.float64)
        return float(np.mean(v)) * scale if v.size else float("nan")

    head = ["filter"]
    for world, noise, _ in cols:
        head.append(f"{world} {noise}" + (" (reference)" if noise == GAUSSIAN else " (x ref)"))
    rows, keys = [], []
    for f in filters:
        cells, k = [f"`{f}`"], [float("nan")]
        for world, noise, name in cols:
            v = mean(f, name)
            ref_name = f"librsf[noise={GAUSSIAN},set={world}]"
            ref = mean(f, ref_name) if ref_name in names else float("nan")
            if noise == GAUSSIAN or not np.isfinite(ref) or ref <= 0:
                cells.append(tb.num(v))
            else:
                cells.append(f"{tb.num(v)} ({tb.num(v / ref, 2)})")
            k.append(v)
        if any(np.isfinite(x) for x in k[1:]):
            rows.append(tuple(cells))
            keys.append(tuple(k))
    if not rows:
        return None
    return Table(
        tuple(head),
        tuple(rows),
        caption=(
            "Robustness to non-Gaussian range noise (libRSF M3500 / W3500; reference: simulation): ATE (cm) per "
            "noise type, in brackets the ratio to the same filter's ATE under the generated Gaussian noise of the "
            "declared variance (0.25 m^2) in the same world"
        ),
        sort_keys=tuple(keys),
    )
