"""Localization filters for locbench (folder ``filters/``, imported as ``locbench.filters``).

The common interface lives in :mod:`locbench.filters.base`; one module per estimator beside it.
Filters are registered lazily (by import path) in :mod:`locbench.registry`, so importing this
package does not import any estimator or its optional dependencies.
"""
