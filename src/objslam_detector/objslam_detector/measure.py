"""Slice angles of a blob, measured to a fraction of a panorama pixel.

A vertical cylinder's silhouette edges are panorama columns and its lowest/highest
points lie on the rims at the centre column. The binary mask only says which pixels
passed the colour gate; the edge is refined where the chroma (max - min of R, G, B)
crosses halfway between the object's level and the background's: blending a colour with
a grey scales its chroma, so the half-level crossing is where the object covers half a
pixel, whatever the gate's saturation floor. The left and right edges are averaged over
the rows of full width (each row samples the original pixel grid at another phase); the
top and bottom come from a quadratic fitted to the rim over the central columns.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import UnifiedCamera
from objslam_common.geometry import wrap_angle
from objslam_common.records import SliceMeasurement
from objslam_detector.blobs import Blob, strip
from objslam_detector.panorama import Panorama

MARGIN_PX = 3
# Below this chroma step (grey levels) between object and surroundings the crossing is noise.
_MIN_CONTRAST = 20.0
_TWO_PI = 2.0 * math.pi
# Rim extremes are fitted over this central part of the width, from at least this many columns.
_CENTRAL_FRACTION = 0.6
_MIN_FIT_COLUMNS = 4
# A rim whose fit rises this much from the centre to the sides has its extreme at the sides.
_SIDE_EXTREME_PX = 1.0
_OUTSIDE_IN = np.arange(-3, 3)  # samples around an edge: three outside, three inside the blob
_SAMPLES = len(_OUTSIDE_IN)


def chroma(rgb: NDArray[np.uint8]) -> NDArray[np.float32]:
    return rgb.max(axis=-1).astype(np.float32) - rgb.min(axis=-1).astype(np.float32)


def crossing_offsets(values: NDArray[np.float32]) -> NDArray[np.float64]:
    """Sub-pixel edge positions from (N, 6) chroma samples ordered from outside to inside.

    The samples are three background pixels, then the first three pixels of the blob.
    The levels are read at the ends, three pixels from the blob's boundary: a compressed
    image (JPEG halves the colour resolution) smears colour across the edge, and levels
    read closer in would pull the half level outwards. The edge is where the chroma
    crosses halfway between the levels, measured in pixels from the outer boundary of
    the blob's first pixel (negative: further out), on the crossing nearest it. Where the
    contrast is too low it stays on that boundary; it never moves by more than one pixel.
    """
    outside = values[:, 0]
    inside = np.maximum(values[:, -1], values[:, -2])
    half = (0.5 * (inside + outside))[:, None]
    low, high = values[:, :-1], values[:, 1:]
    crosses = (low < half) & (high >= half)
    # Sample k (k = 0 for the first blob pixel) is centred at k + 0.5; interval j runs from sample j - 3.
    centres = np.arange(values.shape[1] - 1) - 2.5
    step = np.where(crosses, high - low, 1.0)
    positions = centres + np.where(crosses, (half - low) / step, 0.0)
    distance = np.where(crosses, np.abs(positions), np.inf)
    nearest = np.argmin(distance, axis=1)
    offset = positions[np.arange(len(values)), nearest]
    usable = (inside - outside >= _MIN_CONTRAST) & np.isfinite(distance.min(axis=1))
    return np.minimum(np.maximum(np.where(usable, offset, 0.0), -1.0), 1.0)


def silhouette_edges(
    chroma_roi: NDArray[np.float32], own: NDArray[np.bool_], bottom_above_camera: bool = False
) -> tuple[float, float, float, float]:
    """Left, right, top, bottom edges (ROI pixel-boundary coordinates) of a blob with a margin of background.

    Left and right are means over the rows where the blob is (nearly) widest; top and
    bottom come from the central columns (``_extreme``); only a lower edge above the
    camera can be the rim of a wider table in front, extreme at the sides. All samples
    are gathered at once: blobs are small and numerous, and array calls are what costs.
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
            np.repeat(full, _SAMPLES),
            np.repeat(full, _SAMPLES),
            (top[cols, None] + steps).ravel(),
            (bottom[cols, None] - steps).ravel(),
        ]
    )
    gather_cols = np.concatenate(
        [
            (first[full, None] + steps).ravel(),
            (last[full, None] - steps).ravel(),
            np.repeat(cols, _SAMPLES),
            np.repeat(cols, _SAMPLES),
        ]
    )
    offsets = crossing_offsets(chroma_roi[gather_rows, gather_cols].reshape(-1, _SAMPLES))
    n_full, n_cols_present = len(full), len(cols)
    left_off = offsets[:n_full]
    right_off = offsets[n_full : 2 * n_full]
    top_off = offsets[2 * n_full : 2 * n_full + n_cols_present]
    bottom_off = offsets[2 * n_full + n_cols_present :]
    left = float((first[full] + left_off).mean())
    right = float((last[full] + 1 - right_off).mean())
    column_centres = cols + 0.5
    top_edge = _extreme(column_centres, top[cols] + top_off, float(top[cols].min()), (left, right), False)
    lowest = -float(bottom[cols].max() + 1)
    bottom_edge = -_extreme(
        column_centres, -(bottom[cols] + 1 - bottom_off), lowest, (left, right), bottom_above_camera
    )
    return left, right, top_edge, bottom_edge


def _extreme(
    columns: NDArray[np.floating],
    edge: NDArray[np.float64],
    binary: float,
    sides: tuple[float, float],
    may_peak_at_sides: bool,
) -> float:
    """Outermost value of a rim's edge over the silhouette's width (smaller is further out).

    An object's own rims are symmetric about its bearing and most extreme there, at the
    silhouette's centre; a wider rim in front (the table under an object) is most
    extreme at the silhouette's sides. Single columns are dithered and stair-stepped by
    the image's pixel grid, so a quadratic is fitted to the central columns: its value
    at the centre, or at the sides when it may and clearly curves that way.
    """
    left, right = sides
    centre, half = 0.5 * (left + right), 0.5 * (right - left)
    central = np.abs(columns - centre) <= _CENTRAL_FRACTION * half
    if np.count_nonzero(central) < _MIN_FIT_COLUMNS:
        return float(edge.min())
    c0, c1, c2 = _quadratic_fit(columns[central] - centre, edge[central])
    extreme = c0
    if may_peak_at_sides and -c2 * half * half >= _SIDE_EXTREME_PX:
        extreme = min(c0 - c1 * half + c2 * half * half, c0 + c1 * half + c2 * half * half)
    # A fit gone wild (a blob of odd shape) must not move the edge far from the pixels.
    return min(max(extreme, binary - 1.0), binary + 1.0)


def _quadratic_fit(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[float, float, float]:
    """Least-squares ``y = c0 + c1 x + c2 x^2`` by the normal equations and Cramer's rule.

    Plain Python: a handful of points per blob, where array calls would cost more.
    """
    s0 = s1 = s2 = s3 = s4 = t0 = t1 = t2 = 0.0
    for xi, yi in zip(x.tolist(), y.tolist(), strict=True):
        x2 = xi * xi
        s0 += 1.0
        s1 += xi
        s2 += x2
        s3 += x2 * xi
        s4 += x2 * x2
        t0 += yi
        t1 += xi * yi
        t2 += x2 * yi
    det = s0 * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2)
    if abs(det) < 1e-12:
        return t0 / s0, 0.0, 0.0
    c0 = (t0 * (s2 * s4 - s3 * s3) - s1 * (t1 * s4 - s3 * t2) + s2 * (t1 * s3 - s2 * t2)) / det
    c1 = (s0 * (t1 * s4 - t2 * s3) - t0 * (s1 * s4 - s3 * s2) + s2 * (s1 * t2 - t1 * s2)) / det
    c2 = (s0 * (s2 * t2 - s3 * t1) - s1 * (s1 * t2 - s2 * t1) + t0 * (s1 * s3 - s2 * s2)) / det
    return c0, c1, c2


def image_angle(camera: UnifiedCamera, azimuth_rad: float) -> float:
    """Angle in the image (counter-clockwise from +u, v up) where an azimuth appears; the azimuth if fx == fy."""
    return float(np.arctan2(camera.fy * np.sin(azimuth_rad), camera.fx * np.cos(azimuth_rad)))


def measure(
    blob: Blob,
    label: str,
    rgb_panorama: NDArray[np.uint8],
    pano: Panorama,
    truncated: bool,
    *,
    truncated_confidence: float,
    cut_edges: int = 0,
) -> SliceMeasurement:
    """The slice of a blob: full azimuth extent and lowest/highest elevation of its silhouette."""
    m = MARGIN_PX
    row_lo = max(blob.row0 - m, 0)
    row_hi = min(blob.row0 + blob.rows + m, pano.rows)
    own = np.zeros((row_hi - row_lo, blob.cols + 2 * m), dtype=bool)
    own[blob.row0 - row_lo : blob.row0 - row_lo + blob.rows, m : m + blob.cols] = blob.mask
    roi = chroma(strip(rgb_panorama, slice(row_lo, row_hi), blob.col0 - m, blob.col0 + blob.cols + m))
    if blob.row0 - row_lo < m or row_hi - (blob.row0 + blob.rows) < m:
        # At the panorama's top or bottom there is no background to refine against: pad with none.
        roi = np.pad(roi, ((m, m), (0, 0)))
        own = np.pad(own, ((m, m), (0, 0)))
        row_lo -= m
    bottom_above_camera = bool(pano.row_elevation(blob.row0 + blob.rows) > 0.0)
    left, right, top, bottom = silhouette_edges(roi, own, bottom_above_camera)
    az_start = float(wrap_angle(pano.column_azimuth(blob.col0 - m + left)))
    width = (right - left) * pano.azimuth_step_rad
    el_top = float(pano.row_elevation(row_lo + top))
    el_bottom = float(pano.row_elevation(row_lo + bottom))
    camera = pano.camera
    # The image-space sector (for overlays) is the omnidirectional image's ring sector; other
    # models' overlays project the slice's corners instead (objslam_detector.overlay).
    angle_start = angle_end = radius_inner = radius_outer = 0.0
    if isinstance(camera, UnifiedCamera):
        angle_start = image_angle(camera, az_start)
        angle_end = angle_start + (image_angle(camera, az_start + width) - angle_start) % _TWO_PI
        radius_inner, radius_outer = float(camera.radius_px(el_bottom)), float(camera.radius_px(el_top))
    confidence = blob.fill_ratio * (truncated_confidence if truncated else 1.0)
    return SliceMeasurement(
        label=label,
        confidence=float(np.clip(confidence, 0.0, 1.0)),
        bearing_rad=float(wrap_angle(az_start + 0.5 * width)),
        angular_width_rad=float(width),
        elevation_bottom_rad=el_bottom,
        elevation_top_rad=el_top,
        radius_inner_px=radius_inner,
        radius_outer_px=radius_outer,
        angle_start_rad=angle_start,
        angle_end_rad=angle_end,
        pixel_count=blob.pixel_count,
        truncated=truncated,
        cut_edges=cut_edges,
    )
