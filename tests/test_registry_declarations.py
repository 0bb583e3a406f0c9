"""What the suites and the docs read from the filter and dataset classes: every filter list in the order it had
when the lists were written by hand, the kidnap and main-comparison configurations as each class declares them,
and the generated lists of README.md and docs/design.md as the classes make them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from locbench.core.spec import format_spec
from locbench.filters.base import FilterDoc
from locbench.present import catalog
from locbench.registry import DATASETS, FILTERS, resolve_filter
from locbench.suites import SUITES, all_filters, comparison_filters, kidnap_filters

ROOT = Path(__file__).resolve().parents[1]

#: The package's filters in the order the registry listed them by hand (every suite's "every filter").
EVERY_FILTER = (
    "odometry",
    "ekf_landmarks",
    "ukf_landmarks",
    "iekf_landmarks",
    "ekf_lines",
    "ekf_icp",
    "kf_linear",
    "pf",
    "gtsam_fls",
)
#: Suite kidnap's filters as they were written out in bench/suites.py.
KIDNAP = (
    *EVERY_FILTER[:7],
    "pf[augmented=true]",
    "pf[augmented=true,inject=sensor,inject_pairs=true]",
    "pf[adaptive=kld,augmented=true,inject=sensor,inject_pairs=true]",
    "gtsam_fls",
)


def _readable() -> bool:
    """Whether every class the package declares imports here (the docs are generated where they all do)."""
    return all(reg.class_of(i) is not None for reg in (FILTERS, DATASETS) for i in reg.package_ids())


def test_every_filter_list_keeps_its_order() -> None:
    assert FILTERS.package_ids() == list(EVERY_FILTER)
    assert all_filters() == EVERY_FILTER
    assert comparison_filters() == (*EVERY_FILTER, "ekf_landmarks[association=nearest]", "pf[adaptive=kld]")
    assert kidnap_filters() == KIDNAP
    assert SUITES["default"].blocks[0].filters == comparison_filters()
    assert SUITES["kidnap"].blocks[0].filters == KIDNAP
    assert SUITES["consistency"].blocks[0].filters == EVERY_FILTER
    assert [b.filters[: len(EVERY_FILTER)] for b in SUITES["recorded"].blocks] == [EVERY_FILTER] * 2


def test_datasets_are_listed_by_id() -> None:
    assert DATASETS.package_ids() == sorted(DATASETS.package_ids())
    assert {"room", "office", "tiny_line", "tiny_circle", "mrclam", "radish", "textlog"} <= set(DATASETS.package_ids())


def test_each_filters_kidnap_configurations_hold_its_kidnap_configuration() -> None:
    # the summary reads kidnap recovery from the kidnap configuration's runs in suite kidnap: it must be there
    kidnap = {resolve_filter(s).name for s in kidnap_filters()}
    for fid in all_filters():
        cls = FILTERS.class_of(fid)
        own = format_spec(fid, dict(cls.kidnap_params) if cls is not None else {})
        assert resolve_filter(own).name in kidnap, fid


def test_a_subclass_declares_its_own_comparison_configurations() -> None:
    # ukf_landmarks derives from ekf_landmarks' class: it runs its default alone, not the EKF's nearest-neighbour row
    assert [s for s in comparison_filters() if s.startswith("ukf_landmarks")] == ["ukf_landmarks"]


def test_a_filter_that_is_not_compared_leaves_the_comparing_suites(monkeypatch: pytest.MonkeyPatch) -> None:
    cls = FILTERS.load("kf_linear")
    monkeypatch.setattr(cls, "compared", False)
    assert "kf_linear" not in all_filters() and "kf_linear" not in kidnap_filters()
    assert "kf_linear" in FILTERS.package_ids()  # still registered: it runs when named


def _public_modules_after(code: str) -> list[str]:
    """The public modules of locbench.filters and locbench.datasets a fresh process has imported after ``code``."""
    show = "import sys; print(' '.join(sorted(m for m in sys.modules if m.startswith(P) and '._' not in m)))"
    prog = f"P = ('locbench.filters.', 'locbench.datasets.')\n{code}\n{show}"
    out = subprocess.run([sys.executable, "-c", prog], capture_output=True, text=True, check=True, timeout=300)
    return out.stdout.split()


def test_importing_the_suites_and_the_command_line_imports_no_filter_or_dataset() -> None:
    # the splits are declared data (they import the core only), which the suites' site lists read
    assert _public_modules_after("import locbench.cli, locbench.suites") == ["locbench.datasets.splits"]


def test_a_lookup_by_id_imports_that_filters_module_only() -> None:
    imported = _public_modules_after("from locbench.registry import make_filter; make_filter('pf')")
    filters = [m for m in imported if m.startswith("locbench.filters.")]
    assert filters == ["locbench.filters.base", "locbench.filters.pf"]


def test_every_package_filter_declares_its_docs_row() -> None:
    for fid in FILTERS.package_ids():
        cls = FILTERS.class_of(fid)
        if cls is not None:
            assert isinstance(cls.doc, FilterDoc) and cls.doc.prediction and cls.doc.observation, fid
            assert cls.description, fid


@pytest.mark.skipif(not _readable(), reason="a filter or dataset class does not import here: the docs lack its row")
@pytest.mark.parametrize("document", ["README.md", "docs/design.md", "docs/filters.md"])
def test_the_documents_hold_the_generated_lists(document: str) -> None:
    text = (ROOT / document).read_text(encoding="utf-8")
    names = {
        "README.md": ("filters-count", "filters-list"),
        "docs/design.md": ("filters-design-table", "datasets-design-table"),
        "docs/filters.md": ("filters-table",),
    }[document]
    blocks = catalog.doc_blocks()
    for name in names:
        assert f"<!-- gen:{name} -->{blocks[name]}<!-- /gen:{name} -->" in text, (
            f"{document}: block {name!r} is not what the registry makes; "
            "run python tools/docs/readme_results.py --write"
        )


def test_the_generated_lists_follow_the_declarations(monkeypatch: pytest.MonkeyPatch) -> None:
    cls = FILTERS.load("pf")
    monkeypatch.setattr(cls, "doc", FilterDoc("a source", "a | b", "c"))
    table = catalog.filters_table(notes=True)
    assert "| `pf` | a source | a \\| b | c | - |" in table
    assert catalog.filters_list().split(", ")[-2:] == ["`pf`", "`gtsam_fls`"]
    assert catalog.count_text(8) == "eight" and catalog.count_text(13) == "13"
    rows = [ln for ln in catalog.datasets_table().splitlines() if ln.startswith("| `")]
    assert [r.split(" | ")[0] for r in rows] == [f"| `{d}`" for d in DATASETS.package_ids()]
    assert "| `mrclam` | recorded (reference: motion capture) |" in catalog.datasets_table()
    assert "| `room` | synthetic |" in catalog.datasets_table()
