"""Measure ANEES, NLL, ATE and the PCRB of filters on the model-matched worlds (a few seeds, no store).

Usage: python tools/matched_consistency.py FILTER[,FILTER...] DATASET[,DATASET...] SEEDS
Prints, per (dataset, filter), the mean ANEES over the seeds with the chi-square band for that run count,
the RMS over seeds of the ATE, the bound's RMS ATE, and their ratio.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from locbench.metrics import POSE_DOF, anees, chi2_band, nees_at_truth
from locbench.pcrb import pcrb_metrics
from locbench.registry import make_dataset, make_filter
from locbench.runner import run_filter
from locbench.seeding import filter_rng


def main() -> None:
    filters, datasets, n = sys.argv[1].split(","), sys.argv[2].split(","), int(sys.argv[3])
    for dname in datasets:
        built = [make_dataset(dname, s) for s in range(n)]
        bound = [pcrb_metrics(ds)["ate_m"] for ds in built]
        for fname in filters:
            aneess, ates = [], []
            for s, ds in enumerate(built):
                tr = run_filter(make_filter(fname), ds, filter_rng(fname, dname, s))
                gt = ds.ground_truth
                poses = np.column_stack([gt.xy, gt.theta])
                aneess.append(anees(nees_at_truth(tr.t, tr.mean, tr.cov, gt.t, poses)))
                from locbench.metrics import ate

                ates.append(ate(tr.t, tr.mean, gt.t, gt.xy))
            lo, hi = chi2_band(POSE_DOF, n)
            rms_ate = math.sqrt(float(np.mean(np.square(ates))))
            rms_bound = math.sqrt(float(np.mean(np.square(bound))))
            print(
                f"{dname} {fname}: mean ANEES {np.mean(aneess):.3f} band [{lo:.3f}, {hi:.3f}]; "
                f"RMS ATE {rms_ate * 100:.2f} cm, PCRB {rms_bound * 100:.2f} cm, ratio {rms_ate / rms_bound:.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
