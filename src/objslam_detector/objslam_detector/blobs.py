"""Blobs of the class-index panorama: cleaning, connected components, gates.

The panorama is a cylinder: a blob straddling the azimuth seam at +-pi must stay one
blob, so when colour touches both ends the image is rolled to put the seam in the widest
colourless gap before components are found. Components are found once for all classes
(external contours of the any-class mask, cheap on sparse masks); a component holding
several classes (one object partly hiding another) is split per class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from numpy.typing import NDArray

from objslam_detector.config import BlobConfig
from objslam_detector.layers import Part, separate


@dataclass(frozen=True, eq=False)
class Blob:
    """Pixels of one class forming one connected component.

    ``col0`` is the first column in panorama coordinates and may reach past the last
    column when the blob straddles the seam (index panorama arrays modulo their width);
    ``mask`` holds the blob's own pixels inside its bounding box.
    """

    class_index: int  # 1-based, as in the class-index image
    col0: int
    row0: int
    mask: NDArray[np.bool_]
    cut: bool = False  # separated from a nearer object of its class in front of it: partly hidden

    @property
    def rows(self) -> int:
        return self.mask.shape[0]

    @property
    def cols(self) -> int:
        return self.mask.shape[1]

    @cached_property
    def pixel_count(self) -> int:
        return int(np.count_nonzero(self.mask))

    @property
    def fill_ratio(self) -> float:
        return self.pixel_count / self.mask.size


class Segmenter:
    """Finds and gates the blobs of a class-index panorama."""

    def __init__(
        self, config: BlobConfig, azimuth_step_rad: float, elevation_step_rad: float, horizon_row: float
    ) -> None:
        self.config = config
        # Layered separation reads "nearer" as "lower edge lower": true only below the camera.
        self._horizon_row = horizon_row
        self._min_cols = max(1, math.ceil(math.radians(config.min_angular_width_deg) / azimuth_step_rad - 1e-9))
        self._max_cols = math.floor(math.radians(config.max_angular_width_deg) / azimuth_step_rad + 1e-9)
        self._min_rows = max(1, math.ceil(math.radians(config.min_angular_height_deg) / elevation_step_rad - 1e-9))

    def blobs(self, class_index: NDArray[np.uint8]) -> list[Blob]:
        """Gated blobs of a cleaned class-index panorama."""
        coloured = cv2.compare(class_index, 0, cv2.CMP_GT)
        shift = seam_shift(coloured)
        if shift:
            coloured = np.roll(coloured, -shift, axis=1)
            class_index = np.roll(class_index, -shift, axis=1)
        contours, _hierarchy = cv2.findContours(coloured, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        found = []
        for contour in contours:
            x, y, w, h = cv2.boundingRect(contour)
            if w < self._min_cols or h < self._min_rows:
                continue  # no part of it can pass the size gates
            region = np.zeros((h, w), np.uint8)
            cv2.drawContours(region, [contour], 0, 255, thickness=cv2.FILLED, offset=(-x, -y))
            labels = cv2.bitwise_and(class_index[y : y + h, x : x + w], region)
            for k in np.unique(labels):
                if k:
                    found.extend(self._class_components(int(k), labels == k, x + shift, y))
        return [b for b in found if self._passes(b)]

    def _class_components(self, k: int, mask: NDArray[np.bool_], x: int, y: int) -> list[Blob]:
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=8)
        out: list[Blob] = []
        for j in range(1, count):
            bx, by, bw, bh, area = (int(v) for v in stats[j])
            if area >= self.config.min_pixel_count:
                own = labels[by : by + bh, bx : bx + bw] == j
                below_camera = y + by + bh > self._horizon_row
                if self.config.separate_same_class and below_camera:
                    parts = separate(own, self._horizon_row - (y + by))
                else:
                    parts = [Part(0, 0, own, False)]
                out.extend(Blob(k, x + bx + p.col0, y + by + p.row0, p.mask, p.cut) for p in parts)
        return out

    def _passes(self, blob: Blob) -> bool:
        return (
            blob.pixel_count >= self.config.min_pixel_count
            and self._min_cols <= blob.cols <= self._max_cols
            and blob.rows >= self._min_rows
            and blob.fill_ratio >= self.config.min_fill_ratio
        )


def clean(class_index: NDArray[np.uint8], opening_kernel_px: int) -> NDArray[np.uint8]:
    """Class index with speckle and thin fringes removed (opening of the any-class mask)."""
    if opening_kernel_px <= 1:
        return class_index
    coloured = cv2.compare(class_index, 0, cv2.CMP_GT)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (opening_kernel_px, opening_kernel_px))
    return cv2.bitwise_and(class_index, cv2.morphologyEx(coloured, cv2.MORPH_OPEN, kernel))


def seam_shift(mask: NDArray[np.uint8]) -> int:
    """Columns to roll left so that the seam falls in the widest empty run of columns (0: no need)."""
    cols = mask.shape[1]
    if not (mask[:, 0].any() and mask[:, cols - 1].any()):
        return 0
    empty = np.flatnonzero(~mask.any(axis=0))
    if empty.size == 0:
        return 0  # colour all around: nothing sensible to split
    # Circular runs of empty columns: a run ends wherever the next empty column is not adjacent.
    gaps = np.diff(np.concatenate([empty, empty[:1] + cols]))
    run_ends = np.flatnonzero(gaps > 1)
    if run_ends.size == 0:
        return int(empty[0])
    starts = empty[(run_ends + 1) % empty.size]
    ends = empty[run_ends]
    lengths = (ends - starts) % cols + 1
    best = int(np.argmax(lengths))
    return int((starts[best] + lengths[best] // 2) % cols)


def strip(array: NDArray, rows: slice, col_start: int, col_stop: int) -> NDArray:
    """``array[rows, col_start:col_stop]`` with columns taken modulo the width (the panorama wraps)."""
    if 0 <= col_start and col_stop <= array.shape[1]:
        return array[rows, col_start:col_stop]
    return np.take(array[rows], np.arange(col_start, col_stop), axis=1, mode="wrap")
