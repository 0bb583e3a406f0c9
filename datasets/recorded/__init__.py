"""Loaders for recorded datasets, one module per format (folder ``datasets/recorded/``).

Recorded data is read from ``$LOCBENCH_DATA/<dataset folder>``; see ../shared/datasets/SOURCES.md.
"""
