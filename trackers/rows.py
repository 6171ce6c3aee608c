"""Structures of arrays with one row per item (tracks, candidates, pairs)."""

from __future__ import annotations

import functools
from typing import Self

import numpy as np

__all__ = ["RowArrays", "sort_within_groups"]


class RowArrays:
    """Mixin for a frozen dataclass whose every field is an array with one row per item:
    ``take`` and ``concat`` apply to every field alike, so a new field needs no new code."""

    __dataclass_fields__: dict[str, object]

    def __len__(self) -> int:
        return len(getattr(self, _first_field(type(self))))

    def take(self, index: np.ndarray) -> Self:
        """The rows at ``index`` (integer indices or a boolean mask); ``self`` itself when a
        mask keeps every row (the arrays are never written in place)."""
        if index.dtype == bool:
            if index.all():
                return self
            index = np.flatnonzero(index)
        return type(self)(
            **{k: getattr(self, k).take(index, axis=0) for k in self.__dataclass_fields__}
        )

    def concat(self, other: Self) -> Self:
        """These rows followed by ``other``'s."""
        return type(self)(
            **{
                k: np.concatenate([getattr(self, k), getattr(other, k)])
                for k in self.__dataclass_fields__
            }
        )


@functools.cache
def _first_field(cls: type) -> str:
    """The name of a row dataclass's first field (its length is the number of rows)."""
    return next(iter(cls.__dataclass_fields__))  # type: ignore[attr-defined]


def sort_within_groups(
    group: np.ndarray, value: np.ndarray, *, first: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The order that sorts elements by ``group``, then by falling ``value`` (elements where
    the boolean ``first`` is true before the others of their group, whatever their value),
    ties kept in input order; and the rank of each sorted element within its group
    (0 = its group's best)."""
    keys = (-value, group) if first is None else (-value, ~first, group)
    order = np.lexsort(keys)
    g = group[order]
    return order, np.arange(g.size) - np.searchsorted(g, g, side="left")
