"""Measure ANEES, NLL, ATE and the PCRB of filters on the model-matched worlds (a few seeds, no store).

Usage: python tools/measure/matched_consistency.py FILTER[,FILTER...] DATASET[,DATASET...] SEEDS
Prints, per (dataset, filter), the mean ANEES over the seeds with the chi-square band for that run count,
the RMS over seeds of the ATE, the bound's RMS ATE without the laser, and their ratio.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from locbench.core.seeding import filter_rng
from locbench.evaluate.metrics import POSE_DOF, align, anees, ate, chi2_band, nees_at_truth, nll_at_truth
from locbench.evaluate.pcrb import pcrb_metrics
from locbench.registry import make_dataset, make_filter
from locbench.run.runner import incompatibility, run_filter


def main() -> None:
    filters, datasets, n = sys.argv[1].split(","), sys.argv[2].split(","), int(sys.argv[3])
    for dname in datasets:
        built = [make_dataset(dname, s) for s in range(n)]
        # The bound of the sensors the landmark filters use (no laser); see docs/pcrb.md for the full one.
        bound = [pcrb_metrics(ds, laser=False)["ate_m"] for ds in built]
        for fname in filters:
            aneess, ates, nlls = [], [], []
            for s, ds in enumerate(built):
                flt = make_filter(fname)
                why = incompatibility(flt, ds)
                if why:
                    print(f"{dname} {fname}: skipped ({why})")
                    break
                tr = run_filter(flt, ds, filter_rng(fname, dname, s))
                if tr.status != "ok":
                    print(f"{dname} {fname} seed {s}: {tr.status} {tr.message}")
                    continue
                gt = ds.ground_truth
                poses = np.column_stack([gt.xy, gt.theta])
                aligned = align(tr.t, tr.mean, gt.t, poses, tr.cov)
                aneess.append(anees(nees_at_truth(aligned)))
                nlls.append(float(np.mean(nll_at_truth(aligned))))
                ates.append(ate(aligned))
            if not ates:
                continue
            n = len(ates)
            lo, hi = chi2_band(POSE_DOF, n)
            rms_ate = math.sqrt(float(np.mean(np.square(ates))))
            rms_bound = math.sqrt(float(np.mean(np.square(bound))))
            print(
                f"{dname} {fname}: mean ANEES {np.mean(aneess):.3f} band [{lo:.3f}, {hi:.3f}] ({n} runs); "
                f"mean NLL {np.mean(nlls):.2f}; "
                f"RMS ATE {rms_ate * 100:.2f} cm, PCRB {rms_bound * 100:.2f} cm, ratio {rms_ate / rms_bound:.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
