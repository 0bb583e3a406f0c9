"""Synthetic worlds, robot and sensor simulators, and the named scenarios (folder ``datasets/synthetic/``)."""
