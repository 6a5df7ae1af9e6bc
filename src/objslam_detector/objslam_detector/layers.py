"""Separating objects of one class that overlap in the image (one blob, several cylinders).

A vertical cylinder's silhouette in the panorama is a band of columns whose lower and
upper edges (its rims) run smoothly across it, steeply only in its outermost columns.
Two objects of one colour, one partly behind the other, merge into one blob whose edges
jump where one silhouette ends:

- where the lower edge jumps and the upper edge changes too, the nearer object (lower
  edge lower, for objects standing below the camera) ends: the blob is split there;
- where the upper edge jumps up over a stretch that the lower edge does not follow,
  the farther object shows above the nearer one: the pixels above the nearer one's
  upper edge (carried on from beside the stretch) are the farther object's.

A jump of the lower edge under a smooth upper edge, to a level above the horizon, is a
table (taller than the camera) hiding the bottom of one object: that blob stays whole.
The farther part of a separation is marked ``cut``. Edge levels are medians over a few
columns on each side, against pixel dithering, and no part may be narrower than
``MIN_SIDE_COLS`` (rims are steep only there).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

BOTTOM_STEP_PX = 3  # smallest jump of the lower edge (net of its slope)
TOP_CHANGE_PX = 1  # smallest jump of the upper edge (net of its slope) confirming a lower-edge jump
TOP_STEP_PX = 3  # smallest jump of the upper edge where a farther object shows above
MIN_SIDE_COLS = 5
_SPAN = 3  # columns on each side of a boundary whose median gives an edge level


class Part(NamedTuple):
    """A piece of a blob's bounding box: offset of its own box and its pixels."""

    col0: int
    row0: int
    mask: NDArray[np.bool_]
    cut: bool


class _Edges(NamedTuple):
    top: NDArray[np.int64]  # first row of each column
    bottom: NDArray[np.int64]  # last row of each column

    def level(self, which: str, start: int, stop: int) -> float:
        values = getattr(self, which)
        return float(np.median(values[max(start, 0) : min(stop, len(values))]))

    def change(self, which: str, k: int) -> float:
        """Level right of boundary k (between columns k and k + 1) minus level left of it."""
        return self.level(which, k + 1, k + 1 + _SPAN) - self.level(which, k + 1 - _SPAN, k + 1)

    def jump(self, which: str, k: int) -> float:
        """Like ``change`` but net of the edge's slope: lines fitted on each side, compared at the boundary.

        A single rim rises steeply towards the silhouette's ends; its slope, not a jump.
        """
        values = getattr(self, which).astype(float)
        left = np.arange(max(k + 1 - MIN_SIDE_COLS, 0), k + 1)
        right = np.arange(k + 1, min(k + 1 + MIN_SIDE_COLS, len(values)))
        at = k + 0.5
        return _line_at(right, values[right], at) - _line_at(left, values[left], at)


def _line_at(x: NDArray[np.int64], y: NDArray[np.float64], at: float) -> float:
    """A line through (x, y) evaluated at ``at``, fitted robustly (Theil-Sen: median slope, median offset).

    A silhouette's outermost column can be a sliver only a few pixels tall; a least-squares
    line through it would see a jump beside a single object's smooth rim.
    """
    i, j = np.triu_indices(len(x), k=1)
    slope = float(np.median((y[j] - y[i]) / (x[j] - x[i])))
    return float(np.median(y - slope * x) + slope * at)


def separate(mask: NDArray[np.bool_], horizon_row: float, cut: bool = False) -> list[Part]:
    """The objects within one blob's mask (module docstring); just the blob when it is one.

    ``horizon_row`` is where elevation 0 falls, in the mask's row coordinates.
    """
    rows, cols = mask.shape
    if cols < 2 * MIN_SIDE_COLS or not mask.any(axis=0).all():
        return [Part(0, 0, mask, cut)]
    edges = _Edges(np.argmax(mask, axis=0), rows - 1 - np.argmax(mask[::-1], axis=0))
    split = _split(mask, edges, horizon_row)
    if split is None:
        return [Part(0, 0, mask, cut)]
    parts: list[Part] = []
    for piece, far in zip(split, (False, True), strict=True):
        used_rows = np.flatnonzero(piece.any(axis=1))
        used_cols = np.flatnonzero(piece.any(axis=0))
        if used_rows.size == 0:
            continue
        r0, r1, c0, c1 = used_rows[0], used_rows[-1] + 1, used_cols[0], used_cols[-1] + 1
        box = piece[r0:r1, c0:c1]
        # The far part's edges are shaped by the near object in front: only the near part may hold more.
        subs = [Part(0, 0, box, True)] if far else separate(box, horizon_row - r0, cut)
        parts.extend(Part(sub.col0 + int(c0), sub.row0 + int(r0), sub.mask, sub.cut) for sub in subs)
    return parts


def _boundaries(cols: int) -> range:
    """Boundaries k (between columns k and k + 1) leaving MIN_SIDE_COLS on each side."""
    return range(MIN_SIDE_COLS - 1, cols - MIN_SIDE_COLS)


def _split(mask: NDArray[np.bool_], edges: _Edges, horizon_row: float) -> tuple[NDArray, NDArray] | None:
    """(near, far) masks, or None for one object (module docstring)."""
    jump = _bottom_jump(edges)
    raised = _raised_stretch(mask, edges)
    if raised is not None:
        start, stop, far = raised
        if jump is not None and start - 1 <= jump < stop:
            # The far object shows above the near one up to where the near one ends, and alone beyond.
            near_side, _ = _cut_at(mask, edges, jump)
            far = far | (mask & ~near_side)
        return mask & ~far, far
    if jump is None:
        return None
    # Beside the jump the lower edge is another object's base when the upper edge changes
    # there, or when it lies below the camera: what hides the bottom of one object is a
    # table taller than the camera, whose rim is above the horizon.
    left = edges.level("bottom", jump + 1 - _SPAN, jump + 1)
    right = edges.level("bottom", jump + 1, jump + 1 + _SPAN)
    shelf = min(left, right)  # the higher of the two lower edges (rows grow downwards)
    if abs(edges.jump("top", jump)) >= TOP_CHANGE_PX or shelf > horizon_row:
        return _cut_at(mask, edges, jump)
    return None


def _bottom_jump(edges: _Edges) -> int | None:
    """The boundary with the largest sharp jump of the lower edge, if any."""
    best, best_k = 0.0, None
    for k in _boundaries(len(edges.bottom)):
        if abs(int(edges.bottom[k + 1]) - int(edges.bottom[k])) < 2:
            continue  # not sharp: a slope
        jump = abs(edges.jump("bottom", k))
        if jump >= BOTTOM_STEP_PX and jump > best:
            best, best_k = jump, k
    return best_k


def _cut_at(mask: NDArray[np.bool_], edges: _Edges, k: int) -> tuple[NDArray, NDArray]:
    """Split at boundary k: the side whose lower edge is lower (nearer) first."""
    near = np.zeros_like(mask)
    if edges.change("bottom", k) < 0:
        near[:, : k + 1] = mask[:, : k + 1]
    else:
        near[:, k + 1 :] = mask[:, k + 1 :]
    return near, mask & ~near


def _raised_stretch(mask: NDArray[np.bool_], edges: _Edges) -> tuple[int, int, NDArray] | None:
    """Columns [start, stop) where a farther object shows above a nearer one, and its pixels."""
    cols = mask.shape[1]
    for flipped in (False, True):
        work = mask[:, ::-1] if flipped else mask
        e = _Edges(edges.top[::-1], edges.bottom[::-1]) if flipped else edges
        found = _raised_right_of_near(work, e)
        if found is not None:
            start, stop, far = found
            return (cols - stop, cols - start, far[:, ::-1]) if flipped else found
    return None


def _raised_right_of_near(mask: NDArray[np.bool_], edges: _Edges) -> tuple[int, int, NDArray] | None:
    """The near object's own upper edge on the left; a farther one shows above it from a jump on."""
    cols = mask.shape[1]
    top = edges.top.astype(int)
    for j in _boundaries(cols):
        if top[j] - top[j + 1] < TOP_STEP_PX or -edges.change("top", j) < TOP_STEP_PX:
            continue
        if abs(edges.change("bottom", j)) >= BOTTOM_STEP_PX:
            continue  # the lower edge jumps too: a plain split, not something showing above
        left_level = edges.level("top", j + 1 - _SPAN, j + 1)
        # Where the upper edge falls back (the far object ends above the near one), if it does.
        stop, right_level = cols, left_level
        for m in range(j + 1, cols - MIN_SIDE_COLS):
            if top[m + 1] - top[m] >= TOP_STEP_PX and edges.change("top", m) >= TOP_STEP_PX:
                stop, right_level = m + 1, edges.level("top", m + 1, m + 1 + _SPAN)
                break
        columns = np.arange(j + 1, stop)
        level = np.rint(np.interp(columns, [j, stop], [left_level, right_level]))
        rows = np.arange(mask.shape[0])[:, None]
        far = np.zeros_like(mask)
        far[:, j + 1 : stop] = mask[:, j + 1 : stop] & (rows < level[None, :])
        if far.any():
            return j + 1, stop, far
    return None
