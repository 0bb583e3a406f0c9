"""Running: a planned task, the filter pass over a dataset, contained execution, sweeps and their executors,
the store and its provenance, verification, tuning and export."""
