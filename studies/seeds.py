"""The seed convention of every study: tuning seeds below :data:`HELD_OUT_SEED`, held-out
seeds from it up.

Seeds ``0 … HELD_OUT_SEED − 1`` are **tuning** seeds: use them freely while choosing a rule,
a threshold or a constant. Seeds from :data:`HELD_OUT_SEED` up are **held out**: a reported
figure comes from them, after the rule is fixed. A rule changed after looking at held-out
results moves the report to a fresh block (:func:`held_out_block` 2, 3, …), and says so.

A study row and a bench's JSON line record the range that ran (:class:`SeedRange`), so a
reader can tell a tuned figure from a held-out one.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "HELD_OUT_SEED",
    "SeedRange",
    "held_out_block",
    "held_out_seeds",
    "is_held_out",
]

#: The first held-out seed; every seed below it is a tuning seed.
HELD_OUT_SEED = 1_000_000


def is_held_out(seed: int) -> bool:
    """Whether ``seed`` is in the held-out range (``seed ≥ HELD_OUT_SEED``)."""
    return seed >= HELD_OUT_SEED


def held_out_block(block: int = 1) -> int:
    """The first seed of held-out block ``block``: ``block · HELD_OUT_SEED``.

    Block 1 is the first held-out block; a rule changed after looking at its results
    moves the report to block 2, and so on.
    """
    if block < 1:
        raise ValueError(f"held-out blocks are numbered from 1, got {block}")
    return block * HELD_OUT_SEED


@dataclass(frozen=True)
class SeedRange:
    """A run of consecutive seeds, ``first … first + count − 1``, and which kind they are.

    Attributes
    ----------
    first
        The first seed.
    count
        How many seeds.
    """

    first: int
    count: int

    def __post_init__(self) -> None:
        if self.count < 0 or self.first < 0:
            raise ValueError(f"a seed range needs first ≥ 0 and count ≥ 0, got {self}")
        if self.count and is_held_out(self.first) != is_held_out(self.last):
            raise ValueError(
                f"seeds {self.first}…{self.last} straddle HELD_OUT_SEED = {HELD_OUT_SEED}: "
                "a range is all tuning or all held out"
            )

    @property
    def last(self) -> int:
        """The last seed of the range."""
        return self.first + self.count - 1

    @property
    def held_out(self) -> bool:
        """Whether the range is held out."""
        return is_held_out(self.first)

    @property
    def kind(self) -> str:
        """``"held-out"`` or ``"tuning"``."""
        return "held-out" if self.held_out else "tuning"

    def seeds(self) -> range:
        """The seeds, in order."""
        return range(self.first, self.first + self.count)

    def __iter__(self):
        return iter(self.seeds())

    def __len__(self) -> int:
        return self.count

    def to_dict(self) -> dict[str, int | str]:
        """The range as written in a study row or a bench's JSON line."""
        return {"first": self.first, "last": self.last, "count": self.count, "kind": self.kind}

    def __str__(self) -> str:
        return f"{self.kind} seeds {self.first}…{self.last}"


def held_out_seeds(count: int, *, block: int = 1, offset: int = 0) -> SeedRange:
    """``count`` held-out seeds from block ``block``, ``offset`` seeds into it.

    Parameters
    ----------
    count
        How many seeds.
    block
        The held-out block (1: the first; a fresh one after a rule changed on held-out
        results).
    offset
        Seeds skipped at the block's start (a second study in the same block keeps off the
        first one's seeds).

    Returns
    -------
    SeedRange
        The seeds.
    """
    return SeedRange(held_out_block(block) + offset, count)
