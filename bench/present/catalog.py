"""The registry as the documents list it: the filter tables of ``README.md`` and ``docs/design.md``, the README's
list of the filters and ``docs/design.md``'s table of datasets, made from what each class declares.

A filter's row is its class's ``doc`` (:class:`locbench.filters.base.FilterDoc`), in the declared order of the
package's filters (:meth:`locbench.registry.Registry.package_ids`); a dataset's row is its builder's
``description`` and kind. ``tools/docs/readme_results.py`` writes these texts into the documents' generated blocks
(``<!-- gen:NAME -->...<!-- /gen:NAME -->``, :func:`doc_blocks` by name), and ``tests/test_registry_declarations.py``
checks that the committed documents hold them, so a filter or a dataset added as one module is listed once the
tool has run.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from locbench.registry import DATASETS, FILTERS

#: How a count reads in a sentence ("All eight estimators"); larger counts are written in digits.
NUMBER_WORDS = (
    "zero",
    "one",
    "two",
    "three",
    "four",
    "five",
    "six",
    "seven",
    "eight",
    "nine",
    "ten",
    "eleven",
    "twelve",
)


def count_text(n: int) -> str:
    """``n`` as a sentence writes it: a word up to twelve, digits above."""
    return NUMBER_WORDS[n] if 0 <= n < len(NUMBER_WORDS) else str(n)


def _cell(text: str) -> str:
    """A table cell: a ``|`` inside the text escaped, an empty text as ``-``."""
    return text.replace("|", "\\|") if text else "-"


def _table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table on lines of its own (the block's text starts and ends with a line break)."""
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cell(c) for c in r) + " |" for r in rows]
    return "\n" + "\n".join(lines) + "\n"


def package_filters() -> list[tuple[str, Any]]:
    """The package's filters in declared order, each with its class (None where its module does not import here)."""
    return [(fid, FILTERS.class_of(fid)) for fid in FILTERS.package_ids()]


def filter_cells(cls: Any, notes: bool) -> list[str]:
    """A filter's cells after its id: source, prediction, observation (and notes); ``-`` where it declares none."""
    doc = getattr(cls, "doc", None)
    cells = [doc.source, doc.prediction, doc.observation] if doc is not None else ["", "", ""]
    return cells + ([doc.notes if doc is not None else ""] if notes else [])


def filters_table(notes: bool = False) -> str:
    """The filter table: ``README.md``'s (id, source, prediction, observation) or, with ``notes``,
    ``docs/design.md``'s, which adds the notes."""
    head = ["id", "source", "prediction", "observation", *(["notes"] if notes else [])]
    return _table(head, [[f"`{fid}`", *filter_cells(cls, notes)] for fid, cls in package_filters()])


def filters_list() -> str:
    """The package's filter ids in declared order, as code, comma-separated (the README's first paragraph)."""
    return ", ".join(f"`{fid}`" for fid, _ in package_filters())


def dataset_kind(cls: Any) -> str:
    """``synthetic``, ``recorded (reference: KIND)`` or ``your own recording``, from where and how the builder
    is declared."""
    from locbench.datasets.recorded.common import RecordedDataset

    if isinstance(cls, type) and issubclass(cls, RecordedDataset):
        return f"recorded (reference: {cls.reference_kind})"
    if cls is not None and cls.__module__.startswith(f"{DATASETS.package}.synthetic."):
        return "synthetic"
    return "your own recording"


def datasets_table() -> str:
    """Every dataset the package declares, by id: its kind and its one line (``locbench list``'s)."""
    rows = []
    for did in DATASETS.package_ids():
        cls = DATASETS.class_of(did)
        rows.append([f"`{did}`", dataset_kind(cls) if cls is not None else "", DATASETS.summary(did)])
    return _table(["id", "data", "what"], rows)


def doc_blocks() -> dict[str, str]:
    """Every generated block these lists fill, by name: ``filters-count``, ``filters-list`` and ``filters-table``
    (README.md), ``filters-design-table`` and ``datasets-design-table`` (docs/design.md)."""
    return {
        "filters-count": count_text(len(FILTERS.package_ids())),
        "filters-list": filters_list(),
        "filters-table": filters_table(),
        "filters-design-table": filters_table(notes=True),
        "datasets-design-table": datasets_table(),
    }
