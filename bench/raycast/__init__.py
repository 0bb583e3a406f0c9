"""Ray casting in occupancy grids (:mod:`locbench.raycast.cast`), shared by the simulated laser, the scan
database, the ICP filter and the bound; it sits on :mod:`locbench.core` and below filters and datasets."""
