"""A bounded memo for the per-frame path: the last few results by key, the oldest dropped first."""
from __future__ import annotations

from typing import Generic, Hashable, TypeVar

V = TypeVar("V")


class Recent(Generic[V]):
    """The last ``size`` values put, by key; putting one more drops the oldest. The robot's frame asks
    for the same few things several times (the arm's capsules for its joint angles, a person's H36M
    keypoints, a body's separation from the arm) and never for old ones again, so a small FIFO is enough."""

    def __init__(self, size: int):
        self.size = size
        self._values: dict[Hashable, V] = {}

    def get(self, key: Hashable) -> V | None:
        return self._values.get(key)

    def put(self, key: Hashable, value: V) -> V:
        if key not in self._values and len(self._values) >= self.size:
            del self._values[next(iter(self._values))]  # the oldest
        self._values[key] = value
        return value

    def clear(self) -> None:
        self._values.clear()

    def __len__(self) -> int:
        return len(self._values)
