"""A filter is one module: a copy of ``filters/odometry.py`` under a new id, with no other file edited, is listed by
``locbench list``, runs with ``locbench run``, joins the suites that compare every filter and is a row of the
report's summary table.

The copy is installed into the ``locbench.filters`` package path of fresh processes (the package's ``__path__``
extended by a temporary folder before the command line runs), which is what the registry searches; the working
tree is left as it is.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from locbench.report.site import site_markdown
from locbench.run.store import Store
from locbench.suites import SUITES

#: Three fresh processes (list, run, report), about a minute and a half on 2 shared cores.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
NEW_ID = "odometry_copy"

#: Runs ``locbench ARGS...`` with the folder ARGV[1] added to the ``locbench.filters`` package path.
DRIVER = """
import sys
import locbench.filters
locbench.filters.__path__.append(sys.argv[1])
from locbench.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _copy_of_odometry(folder: Path) -> Path:
    """``filters/odometry.py`` copied to ``folder/odometry_copy.py`` with only its declared id changed."""
    text = (ROOT / "filters" / "odometry.py").read_text(encoding="utf-8")
    declared = 'id: ClassVar[str] = "odometry"'
    assert text.count(declared) == 1
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{NEW_ID}.py"
    path.write_text(text.replace(declared, f'id: ClassVar[str] = "{NEW_ID}"'), encoding="utf-8")
    return path


def _locbench(extra: Path, *args: str) -> str:
    """The output of ``locbench ARGS`` in a fresh process that sees ``extra`` as part of ``locbench.filters``."""
    proc = subprocess.run(
        [sys.executable, "-c", DRIVER, str(extra), *args], capture_output=True, text=True, timeout=900, check=False
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


@pytest.fixture(scope="module")
def extra(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("extra_filters")
    _copy_of_odometry(folder)
    return folder


def test_the_copy_is_listed_and_joins_the_comparing_suites(extra: Path) -> None:
    out = _locbench(extra, "list")
    lines = {ln.split()[0]: ln for ln in out.splitlines() if ln.startswith("  ") and ln.split()}
    assert NEW_ID in lines and "dead reckoning from odometry increments" in lines[NEW_ID]
    assert "unavailable" not in lines[NEW_ID]
    # suite default runs every compared filter on room and office, 20 seeds each: 40 runs more than without it
    default = next(ln for ln in out.splitlines() if ln.split()[:1] == ["default"])
    assert int(default.split()[1]) == SUITES["default"].runs + 2 * 20


def test_the_copy_runs_and_the_summary_table_lists_it(extra: Path, tmp_path: Path) -> None:
    results = tmp_path / "results"
    out = _locbench(
        extra, "run", "--filter", "odometry", NEW_ID, "--dataset", "tiny_line", "--seeds", "2",
        "--results", str(results), "--no-progress",
    )  # fmt: skip
    assert "4 runs" in out and "4 ok" in out, out
    store = Store(results)
    runs = {(r.meta["filter"], r.meta["seed"]): r for r in map(store.read_run, store.iter_runs())}
    assert sorted(runs) == [("odometry", 0), ("odometry", 1), (NEW_ID, 0), (NEW_ID, 1)]
    for seed in (0, 1):  # the same code on the same data: the same estimates, bit for bit
        a, b = runs[("odometry", seed)], runs[(NEW_ID, seed)]
        assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)

    printed = _locbench(extra, "report", "--results", str(results))
    rows = [ln.split()[0] for ln in printed.splitlines() if ln.split()[:1] in (["odometry"], [NEW_ID])]
    assert rows == ["odometry", NEW_ID], printed
    report = site_markdown(results / "summary")
    summary = report[report.index('<a id="summary"></a>') :]
    assert f"| `{NEW_ID}` | odometry only | 2 |" in summary
