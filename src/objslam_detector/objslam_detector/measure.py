"""Slice angles of a blob, measured to a fraction of a panorama pixel.

A vertical cylinder's silhouette edges are panorama columns and its lowest/highest
points lie on the rims at the centre column. The binary mask only says which pixels
passed the colour gate; the edge is refined where the chroma (max - min of R, G, B)
crosses halfway between the object's level and the background's: blending a colour with
a grey scales its chroma, so the half-level crossing is where the object covers half a
pixel, whatever the gate's saturation floor. The left and right edges are averaged over
the rows of full width (each row samples the original pixel grid at another phase); the
top and bottom come from the extreme row's columns.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from objslam_detector.blobs import Blob, strip
from objslam_detector.panorama import Panorama
from objslam_detector.slices import DetectedSlice
from objslam_mapper.camera import UnifiedCamera
from objslam_mapper.geometry import wrap_angle

MARGIN_PX = 3
# Below this chroma step (grey levels) between object and surroundings the crossing is noise.
_MIN_CONTRAST = 20.0
_TWO_PI = 2.0 * math.pi
# Rim extremes are fitted over this central part of the width, from at least this many columns.
_CENTRAL_FRACTION = 0.6
_MIN_FIT_COLUMNS = 4
_OUTSIDE_IN = np.array([-2, -1, 0, 1])  # samples around an edge, from two outside to the second inside


def chroma(rgb: NDArray[np.uint8]) -> NDArray[np.float32]:
    return rgb.max(axis=-1).astype(np.float32) - rgb.min(axis=-1).astype(np.float32)


def crossing_offsets(values: NDArray[np.float32]) -> NDArray[np.float64]:
    """Sub-pixel edge positions from (N, 4) chroma samples ordered from outside to inside.

    The samples are two background pixels, then the first two object pixels. The edge
    is where the chroma crosses halfway between background and object, measured in
    pixels from the outer boundary of the first object pixel (negative: further out).
    Where the contrast is too low it stays on that boundary; it never moves by more than
    one pixel.
    """
    outside, a, b, c = values.T
    inside = np.maximum(b, c)
    half = 0.5 * (inside + outside)
    rising = b >= half
    # Crossing between the centres of the last background and first object pixel, or of the first two object pixels.
    low = np.where(rising, a, b)
    high = np.where(rising, b, c)
    step = high - low
    usable = (inside - outside >= _MIN_CONTRAST) & (step > 0)
    offset = np.where(rising, -0.5, 0.5) + (half - low) / np.where(usable, step, 1.0)
    return np.minimum(np.maximum(np.where(usable, offset, 0.0), -1.0), 1.0)


def silhouette_edges(chroma_roi: NDArray[np.float32], own: NDArray[np.bool_]) -> tuple[float, float, float, float]:
    """Left, right, top, bottom edges (ROI pixel-boundary coordinates) of a blob with a margin of background.

    Left and right are means over the rows where the blob is (nearly) widest; top and
    bottom come from the central columns (``_extreme``). All samples are gathered at
    once: blobs are small and numerous, so the number of array operations is what costs.
    """
    n_rows, n_cols = own.shape
    rows_present = own.any(axis=1)
    cols_present = own.any(axis=0)
    first = np.argmax(own, axis=1)
    last = n_cols - 1 - np.argmax(own[:, ::-1], axis=1)
    top = np.argmax(own, axis=0)
    bottom = n_rows - 1 - np.argmax(own[::-1, :], axis=0)
    width = np.where(rows_present, last - first + 1, 0)
    full = np.flatnonzero(width >= width.max() - 1)
    cols = np.flatnonzero(cols_present)
    steps = _OUTSIDE_IN
    gather_rows = np.concatenate(
        [
            np.repeat(full, 4),
            np.repeat(full, 4),
            (top[cols, None] + steps).ravel(),
            (bottom[cols, None] - steps).ravel(),
        ]
    )
    gather_cols = np.concatenate(
        [
            (first[full, None] + steps).ravel(),
            (last[full, None] - steps).ravel(),
            np.repeat(cols, 4),
            np.repeat(cols, 4),
        ]
    )
    offsets = crossing_offsets(chroma_roi[gather_rows, gather_cols].reshape(-1, 4))
    n_full, n_cols_present = len(full), len(cols)
    left_off, right_off, top_off, bottom_off = np.split(offsets, np.cumsum([n_full, n_full, n_cols_present]))
    left = float(np.mean(first[full] + left_off))
    right = float(np.mean(last[full] + 1 - right_off))
    column_centres = cols + 0.5
    top_edge = _extreme(column_centres, top[cols] + top_off, float(top[cols].min()), left, right)
    lowest = -float(bottom[cols].max() + 1)
    bottom_edge = -_extreme(column_centres, -(bottom[cols] + 1 - bottom_off), lowest, left, right)
    return left, right, top_edge, bottom_edge


def _extreme(
    columns: NDArray[np.float64], edge: NDArray[np.float64], binary: float, left: float, right: float
) -> float:
    """Smallest value of a rim's edge over the silhouette's width (rows grow outwards-negative).

    A rim's extreme lies at the silhouette's centre column (rims of the object itself) or
    at its side edges (the rim of a wider table in front). Single columns are dithered by
    the image's pixel grid, so the extreme of a quadratic fitted to the central columns
    is used rather than the most extreme column.
    """
    centre, half = 0.5 * (left + right), 0.5 * (right - left)
    central = np.abs(columns - centre) <= _CENTRAL_FRACTION * half
    if np.count_nonzero(central) < _MIN_FIT_COLUMNS:
        return float(edge.min())
    c0, c1, c2 = _quadratic_fit(columns[central] - centre, edge[central])
    candidates = [-half, half]
    if c2 > 0 and abs(c1) < 2.0 * c2 * half:
        candidates.append(-c1 / (2.0 * c2))
    extreme = min(c0 + c1 * v + c2 * v * v for v in candidates)
    # A fit gone wild (a blob of odd shape) must not move the edge far from the pixels.
    return min(max(extreme, binary - 1.0), binary + 1.0)


def _quadratic_fit(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[float, float, float]:
    """Least-squares ``y = c0 + c1 x + c2 x^2`` (normal equations: a handful of points, called per blob)."""
    powers = np.vander(x, 5, increasing=True).sum(axis=0)
    normal = powers[[[0, 1, 2], [1, 2, 3], [2, 3, 4]]]
    rhs = np.array([y.sum(), (x * y).sum(), (x * x * y).sum()])
    try:
        c0, c1, c2 = np.linalg.solve(normal, rhs)
    except np.linalg.LinAlgError:
        return float(np.mean(y)), 0.0, 0.0
    return float(c0), float(c1), float(c2)


def image_angle(camera: UnifiedCamera, azimuth_rad: float) -> float:
    """Angle in the image (counter-clockwise from +u, v up) where an azimuth appears; the azimuth if fx == fy."""
    return float(np.arctan2(camera.fy * np.sin(azimuth_rad), camera.fx * np.cos(azimuth_rad)))


def measure(
    blob: Blob,
    label: str,
    rgb_panorama: NDArray[np.uint8],
    pano: Panorama,
    truncated: bool,
    truncated_confidence: float,
) -> DetectedSlice:
    """The slice of a blob: full azimuth extent and lowest/highest elevation of its silhouette."""
    m = MARGIN_PX
    row_lo = max(blob.row0 - m, 0)
    row_hi = min(blob.row0 + blob.rows + m, pano.rows)
    own = np.zeros((row_hi - row_lo, blob.cols + 2 * m), dtype=bool)
    own[blob.row0 - row_lo : blob.row0 - row_lo + blob.rows, m : m + blob.cols] = blob.mask
    roi = chroma(strip(rgb_panorama, slice(row_lo, row_hi), blob.col0 - m, blob.col0 + blob.cols + m))
    if blob.row0 - row_lo < 2 or row_hi - (blob.row0 + blob.rows) < 2:
        # At the panorama's top or bottom there is no background to refine against: pad with none.
        roi = np.pad(roi, ((2, 2), (0, 0)))
        own = np.pad(own, ((2, 2), (0, 0)))
        row_lo -= 2
    left, right, top, bottom = silhouette_edges(roi, own)
    az_start = float(wrap_angle(pano.column_azimuth(blob.col0 - m + left)))
    width = (right - left) * pano.azimuth_step_rad
    el_top = float(pano.row_elevation(row_lo + top))
    el_bottom = float(pano.row_elevation(row_lo + bottom))
    camera = pano.camera
    angle_start = image_angle(camera, az_start)
    angle_end = angle_start + (image_angle(camera, az_start + width) - angle_start) % _TWO_PI
    confidence = blob.fill_ratio * (truncated_confidence if truncated else 1.0)
    return DetectedSlice(
        label=label,
        confidence=float(np.clip(confidence, 0.0, 1.0)),
        bearing_rad=float(wrap_angle(az_start + 0.5 * width)),
        angular_width_rad=float(width),
        elevation_bottom_rad=el_bottom,
        elevation_top_rad=el_top,
        radius_inner_px=float(camera.radius_px(el_bottom)),
        radius_outer_px=float(camera.radius_px(el_top)),
        angle_start_rad=angle_start,
        angle_end_rad=angle_end,
        pixel_count=blob.pixel_count,
        truncated=truncated,
    )
