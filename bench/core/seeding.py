"""Seeds derived from stable names (the pairing protocol).

A dataset's noise depends only on (dataset name, seed), so every filter sees the same data for a
seed; a filter's own randomness depends on (filter name, dataset name, seed). Keys are hashed with
sha256, never with Python's salted ``hash()``.
"""

from __future__ import annotations

import hashlib

import numpy as np


def _words(text: str) -> list[int]:
    digest = hashlib.sha256(text.encode()).digest()
    return [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4)]


def seed_sequence(seed: int, *keys: str) -> np.random.SeedSequence:
    """A SeedSequence from an integer seed and any number of stable string keys."""
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    return np.random.SeedSequence([seed, *_words("\x1f".join(keys))])


def dataset_rng(dataset_name: str, seed: int) -> np.random.Generator:
    """The generator a dataset draws its noise realisation from."""
    return np.random.default_rng(seed_sequence(seed, "dataset", dataset_name))


def filter_rng(filter_name: str, dataset_name: str, seed: int) -> np.random.Generator:
    """The generator handed to a filter's ``reset``."""
    return np.random.default_rng(seed_sequence(seed, "filter", filter_name, dataset_name))


def belief_rng(filter_name: str, dataset_name: str, seed: int) -> np.random.Generator:
    """The runner's own generator for drawing a filter's belief samples (never the filter's: its estimates
    stay those of a run without samples)."""
    return np.random.default_rng(seed_sequence(seed, "belief_sample", filter_name, dataset_name))
