"""Datasets for locbench (folder ``datasets/``, imported as ``locbench.datasets``).

The dataset contract lives in :mod:`locbench.datasets.dataset`; synthetic worlds and sensors in
:mod:`locbench.datasets.synthetic`; loaders for recorded datasets in :mod:`locbench.datasets.recorded`.
A builder class registers its dataset by declaring its ``id``
(:class:`locbench.datasets.dataset.DatasetBuilder`); :mod:`locbench.registry` searches this package's modules on
first need.
"""
