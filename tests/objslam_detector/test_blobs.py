"""Mask cleaning and blob gates (objslam_detector.blobs) on hand-drawn class-index panoramas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objslam_detector import BlobConfig
from objslam_detector.blobs import Segmenter, clean

STEP_RAD = math.radians(0.3)  # the default panorama resolution: 1200 columns all round
ROWS, COLS = 100, 1200
# Defaults at 0.3 deg per pixel: >= 40 px, 4..400 columns, >= 4 rows, fill >= 0.3.
GATES = BlobConfig()


def panorama() -> np.ndarray:
    return np.zeros((ROWS, COLS), np.uint8)


def segment(index: np.ndarray, config: BlobConfig = GATES):
    # Horizon below the last row: every blob is above the camera, so no same-class layer
    # separation runs and only the components and the gates are tested.
    return Segmenter(config, STEP_RAD, STEP_RAD, horizon_row=float(ROWS)).blobs(index)


def test_opening_removes_speckle_and_fringes_and_keeps_blocks_exactly():
    index = panorama()
    index[20:32, 100:112] = 2  # a solid block
    index[25, 112:130] = 2  # a 1-px fringe sticking out of its side
    rng = np.random.default_rng(0)
    for row, col in zip(rng.integers(0, ROWS, 60), rng.integers(300, COLS, 60), strict=True):
        index[row, col] = rng.integers(1, 6)  # isolated pixels
    index[60:62, 500:502] = 3  # a 2x2 speck, smaller than the 3x3 kernel
    block_only = panorama()
    block_only[20:32, 100:112] = 2
    assert np.array_equal(clean(index, 3), block_only)  # class values kept, nothing else left
    assert np.array_equal(clean(index, 1), index)  # kernel 1: cleaning off


def test_a_normal_blob_passes_whole_and_lone_pixels_do_not():
    index = panorama()
    index[20:40, 100:112] = 1
    index[70, 400:800:7] = 1  # uncleaned speckle: no single pixel reaches the size gates
    (blob,) = segment(index)
    assert (blob.class_index, blob.row0, blob.col0, blob.mask.shape) == (1, 20, 100, (20, 12))
    assert blob.mask.all() and blob.pixel_count == 240


def _rectangle(rows: tuple[int, int], cols: tuple[int, int], class_index: int):
    def draw(index: np.ndarray) -> None:
        index[rows[0] : rows[1], cols[0] : cols[1]] = class_index

    return draw


def _ring(index: np.ndarray) -> None:
    index[50:80, 600:630] = 4
    index[52:78, 602:628] = 0  # 224 px in a 30x30 box: fill 0.25


@pytest.mark.parametrize(
    ("draw", "loosened"),
    [
        # size gates
        (_rectangle((20, 26), (300, 306), 2), BlobConfig(min_pixel_count=30)),  # 36 px
        (_rectangle((20, 50), (300, 303), 3), BlobConfig(min_angular_width_deg=0.9)),  # 3 columns
        (_rectangle((20, 23), (300, 330), 3), BlobConfig(min_angular_height_deg=0.9)),  # 3 rows
        (_rectangle((85, 90), (650, 1060), 5), BlobConfig(max_angular_width_deg=125.0)),  # 410 columns
        # shape gate: a hollow outline fills too little of its bounding box
        (_ring, BlobConfig(min_fill_ratio=0.2)),
    ],
    ids=["few-pixels", "narrow", "low", "wide", "sparse"],
)
def test_gates_reject_a_blob_that_only_the_loosened_gate_lets_through(draw, loosened):
    index = panorama()
    index[20:40, 100:112] = 1  # a normal blob, always kept
    draw(index)
    assert [b.class_index for b in segment(index)] == [1]
    # Loosening just that gate keeps it: it was rejected by that gate and no other.
    assert len(segment(index, loosened)) == 2
