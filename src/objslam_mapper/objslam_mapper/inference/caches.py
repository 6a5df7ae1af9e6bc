"""The caches the chain keeps per state, bounded in entries or in bytes (cachetools).

A chain revisits few states many times (a rejected proposal repeats the current one), so
what it computed per state is kept: log targets, graph solutions, how the state's things
appear from every pose. Most of these are small and bounded in entries. How a state's things
appear is (images x things) arrays: on a 900-image run about 5 MB a state, so a bound in
entries let one chain's worker grow past 12 GB; that cache is bounded in bytes
(:func:`lru_bytes`, :func:`nbytes`). Every cached value is a function of its key (and of
what the caller checks on a hit), so what is evicted is computed again, to the same numbers.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Hashable, MutableMapping
from typing import Any, TypeVar

import numpy as np
from cachetools import FIFOCache, LRUCache

logger = logging.getLogger(__name__)

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


def lru(entries: int) -> LRUCache[Any, Any]:
    """At most ``entries`` values; the least recently used goes first."""
    return LRUCache(maxsize=entries)


def fifo(entries: int) -> FIFOCache[Any, Any]:
    """At most ``entries`` values; the first stored goes first (reads do not renew a value)."""
    return FIFOCache(maxsize=entries)


def lru_bytes(max_bytes: int, size_of: Callable[[Any], int] | None = None) -> LRUCache[Any, Any]:
    """Values of at most ``max_bytes`` in all, as ``size_of`` (default :func:`nbytes`) counts them;
    the least recently used go first."""
    return LRUCache(maxsize=max_bytes, getsizeof=size_of or nbytes)


def remember(cache: MutableMapping[K, V], key: K, value: V) -> V:
    """Store ``value`` under ``key`` and return it. A value larger than the whole cache is
    returned without being stored (cachetools refuses it): it is computed again when asked."""
    try:
        cache[key] = value
    except ValueError:
        logger.debug("a value of %d bytes is larger than its cache; not kept", nbytes(value))
    return value


def nbytes(value: object) -> int:
    """Bytes held by the numpy arrays in ``value``: arrays, and tuples, lists and dataclasses
    of them, nested. Other objects count 0 (they are small beside the arrays that are cached)."""
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, (tuple, list)):
        return sum(nbytes(v) for v in value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return sum(nbytes(getattr(value, f.name)) for f in dataclasses.fields(value))
    return 0
