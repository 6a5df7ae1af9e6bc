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
_NEIGHBOURS = np.array([-2, -1, 0, 1])


def chroma(rgb: NDArray[np.uint8]) -> NDArray[np.float32]:
    return rgb.max(axis=-1).astype(np.float32) - rgb.min(axis=-1).astype(np.float32)


def refine_rising_edges(profiles: NDArray[np.float32], first: NDArray[np.intp]) -> NDArray[np.float64]:
    """Sub-pixel edge coordinates (pixel k spans [k, k + 1]) where each profile rises into the object.

    ``first`` is the first object pixel of each profile; profiles need two pixels of
    background before it and one object pixel after it. Falls back to ``first`` where
    the contrast is too low, and never moves an edge by more than one pixel.
    """
    outside, a, b, c = np.take_along_axis(profiles, first[:, None] + _NEIGHBOURS, axis=1).T
    inside = np.maximum(b, c)
    half = 0.5 * (inside + outside)
    rising = b >= half
    # Crossing between the centres of first - 1 and first, or of first and first + 1.
    low = np.where(rising, a, b)
    high = np.where(rising, b, c)
    step = high - low
    usable = (inside - outside >= _MIN_CONTRAST) & (step > 0)
    fraction = (half - low) / np.where(usable, step, 1.0)
    edge = first + np.where(rising, -0.5, 0.5) + fraction
    return np.minimum(np.maximum(np.where(usable, edge, first), first - 1.0), first + 1.0)


def _side_edges(chroma_roi: NDArray[np.float32], own: NDArray[np.bool_]) -> tuple[float, float]:
    """Mean left and right edge columns over the rows where the blob is (nearly) widest."""
    present = own.any(axis=1)
    cols = own.shape[1]
    first = np.argmax(own, axis=1)
    last = cols - 1 - np.argmax(own[:, ::-1], axis=1)
    width = np.where(present, last - first + 1, 0)
    full = width >= width.max() - 1
    left = refine_rising_edges(chroma_roi[full], first[full])
    right = cols - refine_rising_edges(chroma_roi[full, ::-1], cols - 1 - last[full])
    return float(np.mean(left)), float(np.mean(right))


def _outermost(profiles: NDArray[np.float32], mask: NDArray[np.bool_], left: float, right: float) -> float:
    """Outermost edge of a rim, as a row counted from the profiles' outer end (columns are profiles).

    A rim's extreme lies at the silhouette's centre column (rims of the object itself) or at
    its side edges (the rim of a wider table in front). Single columns are dithered by
    the image's pixel grid, so the extreme of a quadratic fitted to the central columns'
    refined edges is used rather than the most extreme column.
    """
    present = mask.any(axis=1)
    first = np.argmax(mask, axis=1)
    binary = float(first[present].min())
    columns = np.arange(len(first)) + 0.5
    centre, half = 0.5 * (left + right), 0.5 * (right - left)
    central = present & (np.abs(columns - centre) <= _CENTRAL_FRACTION * half)
    if np.count_nonzero(central) < _MIN_FIT_COLUMNS:
        return float(refine_rising_edges(profiles[present], first[present]).min())
    x = columns[central] - centre
    edges = refine_rising_edges(profiles[central], first[central])
    c0, c1, c2 = _quadratic_fit(x, edges)
    candidates = [-half, half]
    if c2 > 0 and abs(c1) < 2.0 * c2 * half:
        candidates.append(-c1 / (2.0 * c2))
    extreme = min(c0 + c1 * v + c2 * v * v for v in candidates)
    # A fit gone wild (a blob of odd shape) must not move the edge far from the pixels.
    return float(np.clip(extreme, binary - 1.0, binary + 1.0))


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


def _extreme_edges(
    chroma_roi: NDArray[np.float32], own: NDArray[np.bool_], left: float, right: float
) -> tuple[float, float]:
    """Top and bottom edge rows (ROI coordinates) of the blob."""
    rows = own.shape[0]
    top = _outermost(chroma_roi.T, own.T, left, right)
    bottom = rows - _outermost(chroma_roi.T[:, ::-1], own.T[:, ::-1], left, right)
    return top, bottom


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
    left, right = _side_edges(roi, own)
    if blob.row0 - row_lo >= 2 and row_hi - (blob.row0 + blob.rows) >= 2:
        top, bottom = _extreme_edges(roi, own, left, right)
    else:  # at the panorama's top or bottom: no background to refine against
        top, bottom = blob.row0 - row_lo, blob.row0 - row_lo + blob.rows
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
