"""The Box space of secure.Env when Gymnasium is not installed.

With Gymnasium importable, secure.Env's observation_space and action_space are
gymnasium.spaces.Box; without it they are this Box, which keeps the part of Gymnasium's Box
interface a user of a continuous environment reads: low, high, shape, dtype, sample(), seed(),
contains() / `x in space`, is_bounded(), np_random. Sampling follows Gymnasium's rule per
component: uniform on [low, high] where both are finite, low + Exp(1) or high - Exp(1) where
one side is infinite, N(0, 1) where both are.
"""
from __future__ import annotations

from typing import Optional, Sequence, Tuple, Union

import numpy as np

__all__ = ["Box"]


class Box:
    """A box in R^n: low <= x <= high componentwise (each bound may be +-inf)."""

    def __init__(self, low: Union[float, np.ndarray], high: Union[float, np.ndarray],
                 shape: Optional[Sequence[int]] = None, dtype=np.float32,
                 seed: Optional[int] = None):
        self.dtype = np.dtype(dtype)
        if not np.issubdtype(self.dtype, np.floating):
            raise TypeError(f"Box: dtype = {self.dtype}, must be a floating type")
        if shape is None:
            shape = np.shape(low) if np.ndim(low) else np.shape(high)
        self._shape: Tuple[int, ...] = tuple(int(n) for n in shape)
        low = np.broadcast_to(np.asarray(low, dtype=np.float64), self._shape)
        high = np.broadcast_to(np.asarray(high, dtype=np.float64), self._shape)
        if np.isnan(low).any() or np.isnan(high).any():
            raise ValueError("Box: low and high must not be NaN")
        if (low > high).any():
            raise ValueError(f"Box: low {low} above high {high}")
        self.low = low.astype(self.dtype)
        self.high = high.astype(self.dtype)
        self._np_random: Optional[np.random.Generator] = None
        if seed is not None:
            self.seed(seed)

    @property
    def shape(self) -> Tuple[int, ...]:
        return self._shape

    @property
    def np_random(self) -> np.random.Generator:
        """The generator sample() draws from (seeded by seed(); else from fresh entropy)."""
        if self._np_random is None:
            self.seed(None)
        return self._np_random

    def seed(self, seed: Optional[int] = None) -> list:
        seq = np.random.SeedSequence(seed)
        self._np_random = np.random.Generator(np.random.PCG64(seq))
        return [seq.entropy]

    def is_bounded(self, manner: str = "both") -> bool:
        below, above = bool(np.all(np.isfinite(self.low))), bool(np.all(np.isfinite(self.high)))
        if manner == "both":
            return below and above
        if manner == "below":
            return below
        if manner == "above":
            return above
        raise ValueError(f"Box.is_bounded: manner = '{manner}', must be both, below or above")

    def sample(self) -> np.ndarray:
        """A random point of the box (Gymnasium's rule, above), of this dtype and shape."""
        rng = self.np_random
        low, high = self.low.astype(np.float64), self.high.astype(np.float64)
        lo_ok, hi_ok = np.isfinite(low), np.isfinite(high)
        x = np.empty(self._shape, dtype=np.float64)
        both, neither = lo_ok & hi_ok, ~lo_ok & ~hi_ok
        only_lo, only_hi = lo_ok & ~hi_ok, ~lo_ok & hi_ok
        x[neither] = rng.normal(size=int(neither.sum()))
        x[only_lo] = low[only_lo] + rng.exponential(size=int(only_lo.sum()))
        x[only_hi] = high[only_hi] - rng.exponential(size=int(only_hi.sum()))
        x[both] = rng.uniform(low[both], high[both])
        return np.clip(x, low, high).astype(self.dtype)

    def contains(self, x) -> bool:
        """Whether `x` is a point of the box: its shape, a dtype castable to this one, in bounds."""
        if not isinstance(x, np.ndarray):
            try:
                x = np.asarray(x, dtype=self.dtype)
            except (ValueError, TypeError):
                return False
        return bool(np.can_cast(x.dtype, self.dtype) and x.shape == self._shape
                    and np.all(x >= self.low) and np.all(x <= self.high))

    def __contains__(self, x) -> bool:
        return self.contains(x)

    def __eq__(self, other) -> bool:
        return (isinstance(other, Box) and self._shape == other._shape
                and self.dtype == other.dtype and np.array_equal(self.low, other.low)
                and np.array_equal(self.high, other.high))

    def __repr__(self) -> str:
        def bound(b):
            return str(b.flat[0]) if b.size and np.all(b == b.flat[0]) else str(b)
        return f"Box({bound(self.low)}, {bound(self.high)}, {self._shape}, {self.dtype})"
