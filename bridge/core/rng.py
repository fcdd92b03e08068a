"""Deterministic random streams: one independent generator per (seed, entity, purpose).

Enabling one noise source never shifts another's draws, and a robot's streams do not depend on which
process hosts it.
"""

from __future__ import annotations

import hashlib

import numpy as np


def stream_seed(seed: int, *keys: object) -> int:
    """A 64-bit seed derived from the session seed and a path of keys."""
    h = hashlib.blake2b(repr((seed, *keys)).encode(), digest_size=8)
    return int.from_bytes(h.digest(), "little")


def stream(seed: int, *keys: object) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(stream_seed(seed, *keys)))
