"""Hand-made input files and message checks the malformed-input and fuzz tests share (importable as
``input_support``)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import pytest

from locbench.core.errors import MAX_MESSAGE_CHARS


def grey_png(path: Path, width: int, height: int) -> Path:
    """A grey PNG of ``width`` x ``height`` zero pixels, compressed to a few hundred KB at most."""
    row = b"\x00" + b"\x00" * width
    data = zlib.compress(row * height, 9)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b""))
    return path


def one_line(info: pytest.ExceptionInfo[BaseException], *words: str) -> str:
    """The error's message, after checking it is one bounded line holding every word."""
    msg = str(info.value)
    assert "\n" not in msg and len(msg) <= MAX_MESSAGE_CHARS, msg
    for w in words:
        assert w in msg, msg
    return msg
