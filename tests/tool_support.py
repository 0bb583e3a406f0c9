"""Import a study of ``tools/`` by file name (tools/ is not a package), for the tests that rerun it."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType


def load_tool(name: str) -> ModuleType:
    """The module ``tools/<name>.py``."""
    path = Path(__file__).resolve().parents[1] / "tools" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"_tool_{name}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    # registered first: a dataclass in the tool looks its module up while the class is made
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module
