"""The folder -> package mapping in pyproject.toml stays complete and the import names stay distinct."""

from __future__ import annotations

import tomllib
from pathlib import Path

import locbench

ROOT = Path(__file__).resolve().parents[1]


def _declared() -> tuple[list[str], dict[str, str]]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return cfg["packages"], cfg["package-dir"]


def test_every_package_folder_is_listed() -> None:
    packages, package_dir = _declared()
    folder_of = {pkg: folder for pkg, folder in package_dir.items()}
    expected = set()
    for pkg, folder in folder_of.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder)
            expected.add(".".join([pkg, *rel.parts]) if rel.parts else pkg)
    # a sub-package of locbench that lives in another mapped folder is named by that folder's mapping
    assert expected == set(packages), f"pyproject packages out of date: missing {expected - set(packages)}"


def test_import_names_are_not_the_folder_names() -> None:
    _, package_dir = _declared()
    assert set(package_dir) == {"locbench", "locbench.filters", "locbench.datasets"}
    assert Path(locbench.__file__).parent.name in ("bench", "locbench")


def test_root_package_imports_no_filters_or_datasets() -> None:
    import subprocess
    import sys

    code = (
        "import sys, locbench; print(any(m.startswith(('locbench.filters', 'locbench.datasets')) for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"


def test_readme_and_docs_links_resolve_inside_the_clone() -> None:
    """Every relative link of the README and docs/ names a file of the repository; nothing points outside it."""
    import re

    root = Path(__file__).resolve().parents[1]
    pages = [root / "README.md", *sorted(p for p in (root / "docs").rglob("*.md") if "_build" not in p.parts)]
    bad = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if target.startswith(("http://", "https://", "#", "mailto:")):
                continue
            path = (page.parent / target.split("#", 1)[0]).resolve()
            if not path.exists() or root not in path.parents:
                bad.append(f"{page.name}: {target}")
        bad += [f"{page.name}: mentions ../shared" for _ in re.findall(r"\.\./shared", text)]
    assert not bad, bad
