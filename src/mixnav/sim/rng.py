"""Named, independent random streams from one seed.

``streams(seed).get("imu")`` always gives the same generator for the same
seed and name, whatever other streams exist or in what order they are used,
so adding a noise source to a scenario does not change the others' draws.
"""

from __future__ import annotations

import zlib

import numpy as np


class Streams:
    """Factory of named generators derived from one integer seed."""

    def __init__(self, seed: int):
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.seed = int(seed)

    def get(self, name: str) -> np.random.Generator:
        """A fresh generator for stream ``name`` (same name, same numbers)."""
        key = zlib.crc32(name.encode("utf-8"))
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(key,)))
