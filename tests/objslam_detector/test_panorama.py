"""The unwarped panorama samples the image where the camera model says, and wraps at +-pi."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from objslam_common.cameras.unified import DEFAULT_CAMERA
from objslam_detector import PanoramaConfig
from objslam_detector.blobs import seam_shift
from objslam_detector.panorama import Panorama, highest_visible_elevation

PANO = Panorama.build(DEFAULT_CAMERA, PanoramaConfig())


def test_grid_covers_the_circle_from_low_elevations_to_the_image_corners():
    assert PANO.cols == round(360.0 / PanoramaConfig().azimuth_resolution_deg)
    assert math.isclose(PANO.row_elevation(PANO.rows), math.radians(-80.0), abs_tol=1e-9)
    corner = highest_visible_elevation(DEFAULT_CAMERA)
    assert 0.0 < corner < DEFAULT_CAMERA.max_elevation_rad
    assert PANO.top_elevation_rad >= corner - 1e-9
    assert PANO.top_elevation_rad - PANO.elevation_step_rad < corner


@given(u=st.floats(20, 620), v=st.floats(20, 620))
def test_unwarping_reads_the_pixel_of_each_direction(u, v):
    """A panorama pixel shows the image at camera.project(its azimuth, elevation)."""
    az, el = DEFAULT_CAMERA.unproject(u, v)
    row = PANO.row_of_elevation(el)
    col = PANO.column_of_azimuth(az)
    if not (0.5 <= row < PANO.rows - 1.5):
        return
    # A smooth image (a linear ramp) makes bilinear sampling exact: value = u coordinate.
    ramp_u = np.tile(np.arange(640, dtype=np.float32), (640, 1))
    pano = PANO.unwarp(ramp_u)
    r, c = int(row - 0.5), int(col - 0.5) % PANO.cols
    centre_az = PANO.column_azimuth(c + 0.5)
    centre_el = PANO.row_elevation(r + 0.5)
    u_expected, _ = DEFAULT_CAMERA.project(centre_az, centre_el)
    assert abs(pano[r, c] - u_expected) < 0.05  # fixed-point remap: 1/32 px


def test_pixels_outside_the_image_are_black_and_marked():
    image = np.full((640, 640, 3), 200, np.uint8)
    pano = PANO.unwarp(image)
    assert np.all(pano[~PANO.inside] == 0)
    assert np.all(pano[PANO.inside] > 0)


def test_seam_shift_moves_the_seam_into_the_widest_gap():
    mask = np.zeros((5, 100), np.uint8)
    mask[:, :3] = 255
    mask[:, 97:] = 255  # a blob across the seam
    mask[:, 40:45] = 255
    shift = seam_shift(mask)
    rolled = np.roll(mask, -shift, axis=1)
    assert not rolled[:, 0].any() and not rolled[:, -1].any()
    assert seam_shift(np.zeros((5, 100), np.uint8)) == 0
    assert seam_shift(np.full((5, 100), 255, np.uint8)) == 0  # colour all around: leave it
