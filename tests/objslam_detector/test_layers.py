"""Separating same-class objects in one blob, on hand-made masks (rows grow downwards)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from objslam_detector.layers import separate

HORIZON = 5.0  # rows above this are above the camera


def band(rows: int, cols: int, spans: list[tuple[int, int, int, int]]) -> np.ndarray:
    """Mask with each (col0, col1, top, bottom) band filled (inclusive rows)."""
    mask = np.zeros((rows, cols), bool)
    for c0, c1, top, bottom in spans:
        mask[top : bottom + 1, c0:c1] = True
    return mask


@given(
    width=st.integers(4, 60),
    height=st.integers(4, 60),
    curve=st.integers(0, 4),
    seed=st.integers(0, 10_000),
)
def test_one_cylinder_silhouette_is_never_split(width, height, curve, seed):
    """Rims curved like a cylinder's (steep only at the ends), dithered by one pixel."""
    rng = np.random.default_rng(seed)
    x = np.linspace(-1, 1, width)
    rim = curve * (1 - np.sqrt(np.clip(1 - x * x, 0, 1)))  # sqrt-steep at the tangents
    top = np.rint(rim + rng.integers(0, 2, width)).astype(int)
    bottom = np.rint(height + 4 - rim - rng.integers(0, 2, width)).astype(int)
    mask = np.zeros((height + 10, width), bool)
    for c in range(width):
        mask[top[c] : bottom[c] + 1, c] = True
    parts = separate(mask, HORIZON)
    assert len(parts) == 1 and not parts[0].cut


def test_near_object_beside_a_farther_one_is_split_at_its_edge():
    # Near: columns 0-19, rows 2-40. Far (right): columns 20-34, rows 6-30.
    mask = band(45, 35, [(0, 20, 2, 40), (20, 35, 6, 30)])
    parts = sorted(separate(mask, HORIZON), key=lambda p: p.col0)
    assert [(p.col0, p.mask.shape[1], p.cut) for p in parts] == [(0, 20, False), (20, 15, True)]


def test_farther_object_showing_above_the_nearer_one_gets_those_pixels():
    # Near: columns 0-24, rows 10-40. Far: columns 15-34, rows 2-30 (shows above near from column 15).
    mask = band(45, 35, [(0, 25, 10, 40), (15, 35, 2, 30)])
    parts = sorted(separate(mask, HORIZON), key=lambda p: p.col0)
    near, far = parts
    assert (near.col0, near.mask.shape[1], near.cut) == (0, 25, False)
    assert near.row0 == 10  # its own upper edge, not the far one's
    assert (far.col0, far.mask.shape[1], far.cut) == (15, 20, True)


def test_bottom_hidden_by_a_table_above_the_horizon_keeps_the_object_whole():
    # One object (rows 2-40) whose lower part right of column 20 hides behind a tall table (rim at row 3-4).
    mask = band(45, 35, [(0, 20, 2, 40), (20, 35, 2, 3)])
    mask[:, 20:35] = False
    mask[2:4, 20:35] = True  # only what shows above the table rim
    mask = band(45, 35, [(0, 20, 2, 40), (20, 35, 2, 4)])
    assert len(separate(mask, horizon_row=10.0)) == 1
