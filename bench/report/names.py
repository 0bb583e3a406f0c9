"""The dataset parameters the report's protocols read, and how names are spelled in file names and lists."""

from __future__ import annotations

import hashlib
import re

#: The kidnap protocol's dataset parameter (DESIGN "Kidnap recovery"): variants differing only in it form one
#: recovery-against-distance curve.
KIDNAP_PARAM = "kidnap_m"
#: The protocol's parameter of model-matched worlds: the simulator's noise is the filters' nominal noise.
MATCHED_PARAM = "matched"
NAN = float("nan")


def slug(name: str) -> str:
    """A file-name-safe, bounded stem for a name; long or changed names get a short hash of the full name."""
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "x"
    if s != name or len(s) > 80:
        s = f"{s[:80]}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"
    return s


def seed_ranges(seeds: list[int] | set[int]) -> str:
    """``0-4, 7, 9-10`` for the seeds 0 1 2 3 4 7 9 10."""
    s = sorted(set(seeds))
    parts: list[str] = []
    i = 0
    while i < len(s):
        j = i
        while j + 1 < len(s) and s[j + 1] == s[j] + 1:
            j += 1
        parts.append(str(s[i]) if i == j else f"{s[i]}-{s[j]}")
        i = j + 1
    return ", ".join(parts) if parts else "none"
