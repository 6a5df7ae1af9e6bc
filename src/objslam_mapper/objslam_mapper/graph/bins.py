"""Summing per-slice terms into the blocks of the normal equations at precomputed flat positions."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def bin_sum(bins: NDArray[np.int64], values: NDArray[np.float64], shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Sum ``values`` into a zero array of ``shape`` at the flat positions ``bins`` (same shape as values)."""
    size = int(np.prod(shape))
    # bincount of an empty input is int64 whatever the weights: a graph without slices
    # (no objects) would then get integer blocks.
    summed = np.bincount(bins.ravel(), weights=values.ravel(), minlength=size)
    return summed.astype(np.float64, copy=False).reshape(shape)
