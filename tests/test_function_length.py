"""Layout rule: no function in bench/, filters/ or datasets/ runs past 80 lines without a comment saying why.

A long function says so with a comment ``# long: <why>`` in its body (for example: one pass over the file's
lines whose branches share the parser's state; a compiled kernel whose loops must stay in one frame).
"""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("bench", "filters", "datasets")
MAX_LINES = 80
MARK = "# long:"


def long_functions_without_reason(root: Path = ROOT) -> list[str]:
    """``path:line name (n lines)`` of every function longer than :data:`MAX_LINES` lacking a ``# long:`` comment."""
    found: list[str] = []
    for folder in FOLDERS:
        for path in sorted((root / folder).rglob("*.py")):
            text = path.read_text(encoding="utf-8")
            comments = {
                tok.start[0]
                for tok in tokenize.generate_tokens(io.StringIO(text).readline)
                if tok.type == tokenize.COMMENT and tok.string.lower().startswith(MARK)
            }
            for node in ast.walk(ast.parse(text)):
                if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                assert node.end_lineno is not None
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_LINES and not any(node.lineno <= c <= node.end_lineno for c in comments):
                    found.append(f"{path.relative_to(root)}:{node.lineno} {node.name} ({lines} lines)")
    return found


def test_long_functions_say_why() -> None:
    missing = long_functions_without_reason()
    assert not missing, "functions over 80 lines without a '# long: <why>' comment:\n" + "\n".join(missing)


def test_the_rule_catches_a_long_function(tmp_path: Path) -> None:
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_LINES))
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "m.py").write_text(f"def f():\n{body}    return 0\n\n\ndef g():\n    # long: a test\n{body}")
    assert long_functions_without_reason(tmp_path) == ["bench/m.py:1 f (82 lines)"]
