"""Localization filters for locbench (folder ``filters/``, imported as ``locbench.filters``).

The common interface lives in :mod:`locbench.filters.base`; one module per estimator beside it. An
estimator's class registers it by declaring its ``id`` (:class:`locbench.filters.base.Filter`):
:mod:`locbench.registry` searches this package's modules on first need, so importing this package does
not import any estimator or its optional dependencies.
"""
