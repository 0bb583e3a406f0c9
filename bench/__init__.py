"""locbench: a comparative benchmark of 2-D mobile-robot localization filters.

The package root lives in the ``bench/`` folder and is imported as ``locbench``;
``filters/`` is ``locbench.filters`` and ``datasets/`` is ``locbench.datasets``.
This module imports neither, so that importing the package stays cheap and free of cycles.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
