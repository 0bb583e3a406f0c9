"""What a recorded dataset's reference is, and the libRSF robustness table.

Reference kinds
---------------
Every recorded dataset is scored against its reference trajectory, and the kind of that reference says how far the
scores can be trusted: **motion capture** (Vicon), **GPS**, **survey** (surveyed marks), **SLAM** (another
estimator's output, whose map is often built from the same log), **simulation** (exact truth of simulated data) and
**not stated** (a truth whose method the dataset does not give). A recorded builder names its kind in its class
attribute ``reference_kind``, or per set in ``metadata["reference_kind"]``. The report's recorded section shows one
group of tables per kind and says the kind in every caption; the summary's "recorded median ATE" counts only
:data:`INDEPENDENT_KINDS` (measured truth of a recording), never a SLAM reference or a simulation.

Semi-synthetic data (``metadata["semi_synthetic"]``: recorded scans with simulated motion increments) are marked
wherever their name is shown.

Robustness table
----------------
ATE (cm) of each filter on each simulated ranging world under each range-noise type (heavy-tailed, multimodal,
skewed) beside the generated Gaussian reference of the same world (``noise=gaussian``: the declared 0.25 m^2), and
the ratio to that reference.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from locbench.core.errors import LocbenchError
from locbench.evaluate.metrics import ATE_M, METRICS
from locbench.registry import DATASETS
from locbench.report import tables as tb
from locbench.report.doc import Table

if TYPE_CHECKING:
    from locbench.report.context import Report

#: The reference kinds, in the order the report groups them.
KINDS = ("motion capture", "GPS", "survey", "not stated", "SLAM", "simulation")
#: Kinds of independent, measured ground truth of a recording: the only ones the summary's recorded median counts.
INDEPENDENT_KINDS = frozenset({"motion capture", "GPS", "survey", "not stated"})
#: The noise types of the robustness table, then the Gaussian reference.
NOISE_TYPES = ("heavy-tailed", "multimodal", "skewed")
GAUSSIAN = "gaussian"


def reference_kind(dataset_id: str, metadata: dict[str, Any], truth_label: str) -> str:
    """The kind of a dataset's reference (module docstring); a SLAM truth label is SLAM whatever else is said.

    The stored ``metadata["reference_kind"]`` first, else the builder's
    :attr:`~locbench.datasets.recorded.common.RecordedDataset.reference_kind`, else "not stated".
    """
    if truth_label == "SLAM reference":
        return "SLAM"
    kind = metadata.get("reference_kind")
    if not (isinstance(kind, str) and kind in KINDS):
        try:
            kind = getattr(DATASETS.load(dataset_id), "reference_kind", "")
        except LocbenchError:  # a dataset no longer registered (or not installed): nothing more is known
            kind = ""
    return kind if isinstance(kind, str) and kind in KINDS else "not stated"


def semi_synthetic(metadata: dict[str, Any]) -> bool:
    """Whether the dataset's motion data is simulated on top of the recording (``metadata["semi_synthetic"]``)."""
    return metadata.get("semi_synthetic") is True


def dataset_reference_kind(rep: Report, dataset: str) -> str:
    """:func:`reference_kind` of a stored dataset name, from its stored truth (else its id)."""
    ident, meta, label = rep.truth_meta(dataset)
    return reference_kind(ident or rep.col.datasets[dataset].spec.ident, meta, label)


def recorded_header(rep: Report, dataset: str) -> str:
    """A recorded dataset's column header: its name, marked when it is semi-synthetic."""
    semi = " (semi-synthetic)" if semi_synthetic(rep.truth_meta(dataset)[1]) else ""
    return f"`{rep.col.display(dataset)}`{semi}"


def kind_caption(kind: str) -> str:
    """The words every table of a group carries."""
    return f"reference: {kind}" + (
        " (another estimator's output, not independent ground truth)" if kind == "SLAM" else ""
    )


def robustness_table(df: pd.DataFrame, filters: list[str], noise_of: dict[str, tuple[str, str]]) -> Table | None:
    """ATE per filter per noise type beside the Gaussian reference, per world; None without such datasets.

    ``df`` holds the stored metric rows (columns dataset, filter, metric, value); ``noise_of`` maps a dataset name to
    its (world, noise type) as its loader stored them (``metadata["range_noise"]``).
    """
    worlds = sorted({w for w, _ in noise_of.values()})
    order = {n: i for i, n in enumerate((*NOISE_TYPES, GAUSSIAN))}
    cols = sorted(
        ((w, n, d) for d, (w, n) in noise_of.items() if n in order), key=lambda c: (worlds.index(c[0]), order[c[1]])
    )
    if not cols:
        return None
    ref_of = {w: d for d, (w, n) in noise_of.items() if n == GAUSSIAN}
    scale = METRICS[ATE_M].scale
    ate = df[df["metric"] == ATE_M]

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
            ref = mean(f, ref_of[world]) if world in ref_of else float("nan")
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
            "Robustness to non-Gaussian range noise (reference: simulation): ATE (cm) per noise type, in brackets the "
            "ratio to the same filter's ATE under the generated Gaussian noise of the declared variance in the same "
            "world"
        ),
        sort_keys=tuple(keys),
    )
