"""Datasets for locbench (folder ``datasets/``, imported as ``locbench.datasets``).

The dataset contract lives in :mod:`locbench.datasets.dataset`; synthetic worlds and sensors in
:mod:`locbench.datasets.synthetic`; loaders for recorded datasets in :mod:`locbench.datasets.recorded`.
Datasets are registered lazily in :mod:`locbench.registry`.
"""
