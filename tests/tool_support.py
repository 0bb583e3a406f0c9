"""Run a script of ``tools/`` as a person does (``python tools/KIND/NAME.py ARGS``), for the tests of a tool."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

#: The checkout's ``tools`` folder.
TOOLS = Path(__file__).resolve().parents[1] / "tools"


def run_tool(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run ``tools/<script>`` (``"measure/budget_floor.py"``) with ``args`` in this interpreter; its exit code,
    output and error text (nothing raised on a non-zero exit)."""
    path = TOOLS / script
    assert path.is_file(), path
    return subprocess.run([sys.executable, str(path), *args], capture_output=True, text=True, check=False)
