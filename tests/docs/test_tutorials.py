"""Every tutorial's commands run as written: the ``$`` lines of its ``console`` blocks, in order, in one shell, from
an empty working folder, with this interpreter's locbench first on the PATH."""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TUTORIALS = ROOT / "docs" / "tutorials"
#: A fenced ``console`` block of a Markdown page.
CONSOLE = re.compile(r"^```console\n(.*?)^```", re.MULTILINE | re.DOTALL)


def commands(page: Path) -> list[str]:
    """The shell commands of a page: each ``$ `` line of its console blocks (a trailing ``\\`` continues it)."""
    out: list[str] = []
    for block in CONSOLE.findall(page.read_text(encoding="utf-8")):
        pending: str | None = None
        for line in block.splitlines():
            if pending is not None:
                pending += "\n" + line
            elif line.startswith("$ "):
                pending = line[2:]
            else:
                continue
            if not pending.endswith("\\"):
                out.append(pending)
                pending = None
    return out


def pages() -> list[Path]:
    return sorted(p for p in TUTORIALS.glob("*.md") if p.name != "index.md")


def test_every_tutorial_is_in_the_index_and_has_commands() -> None:
    index = (TUTORIALS / "index.md").read_text(encoding="utf-8")
    for page in pages():
        assert re.search(rf"^{re.escape(page.stem)}$", index, re.MULTILINE), f"{page.name} is not in the index"
        assert commands(page), f"{page.name} has no command"


def test_the_parser_reads_continuations_and_skips_output() -> None:
    page = "text\n```console\n$ echo a \\\n  b\nprinted\n$ true\n```\n```bash\n$ not this\n```\n"
    blocks = CONSOLE.findall(page)
    assert len(blocks) == 1 and "not this" not in blocks[0]


@pytest.mark.slow
@pytest.mark.parametrize("page", pages(), ids=lambda p: p.stem)
def test_tutorial_commands_run_as_written(page: Path, tmp_path: Path) -> None:
    # the plugin tutorial installs the example plugin "from the root of a clone": give the folder the same examples
    shutil.copytree(
        ROOT / "examples", tmp_path / "examples", ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__")
    )
    script = "set -euo pipefail\n" + "\n".join(f"printf '+ %s\\n' {shlex.quote(c)}\n{c}" for c in commands(page))
    env = {k: v for k, v in os.environ.items() if k not in ("LOCBENCH_DATA", "PYTHONPATH")}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    proc = subprocess.Popen(
        ["bash", "-c", script],
        cwd=tmp_path,
        env=env,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    try:
        out, _ = proc.communicate(timeout=900)
    finally:
        # what a tutorial started in the background (a dask scheduler and its workers) ends with it
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        if proc.returncode is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, f"{page.name}: a command failed:\n{out[-4000:]}"
