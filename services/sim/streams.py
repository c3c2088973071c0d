"""Random numbers keyed by what they are for (common random numbers across methods).

An experiment compares methods trial by trial: for one trial index, the human of every method must
draw the same task time, the same focus intervals and the same outcome for "the k-th decision about
robot r at door d". A single generator drawn in the order things happen cannot give that: a method
that makes one more draw early shifts every draw after it. So each draw comes from its own stream,
named by what it is for — ``("task",)``, ``("focus",)``, ``("declare", i)``,
``("seen", door, robot, k)``, ``("blind", minute)`` — and derived from the run's seed alone.

A stream is a BLAKE2b hash of the seed and the key's parts as text: stable across platforms,
Python versions and processes (no ``hash()``), and independent of how many other draws were made.
"""

from __future__ import annotations

import hashlib

import numpy as np

_UNIT = 2.0**-53


def _digest(seed: int, key: tuple[object, ...], size: int) -> bytes:
    text = "|".join([str(seed), *(str(part) for part in key)])
    return hashlib.blake2b(text.encode("utf-8"), digest_size=size).digest()


class Streams:
    """The random streams of one run, all derived from ``seed``."""

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)

    def uniform(self, *key: object) -> float:
        """One number in [0, 1), the same for the same seed and key whatever was drawn before."""
        return (int.from_bytes(_digest(self.seed, key, 8), "big") >> 11) * _UNIT

    def generator(self, *key: object) -> np.random.Generator:
        """A numpy generator of its own for a group of draws made together (e.g. the focus intervals)."""
        words = np.frombuffer(_digest(self.seed, key, 16), dtype=">u4").astype(np.uint32)
        return np.random.default_rng(np.random.SeedSequence(words.tolist()))
