"""The report's document blocks: defined in :mod:`locbench.present.docfmt`, which the claims use too."""

from __future__ import annotations

from locbench.present.docfmt import Block, Bullets, DrawFn, Plot, Section, Table, Text

__all__ = ["Block", "Bullets", "DrawFn", "Plot", "Section", "Table", "Text"]
