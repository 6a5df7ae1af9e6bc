"""Colour-blob detection on the unwarped panorama: image + calibration -> slices.

CMVision style: per-class colour gates on the panorama, morphological cleaning,
connected components, size and shape gates; each surviving blob becomes a
SliceMeasurement measured on its silhouette (``measure``).
"""

from __future__ import annotations

import logging
from collections import OrderedDict

import cv2
import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import CameraModel, UnifiedCamera, level_view
from objslam_common.catalog import Catalog, load_catalog
from objslam_common.errors import ConfigError
from objslam_common.records import CUT_BOTTOM, CUT_LEFT, CUT_RIGHT, CUT_TOP, SliceMeasurement
from objslam_detector.blobs import Blob, Segmenter, clean, strip
from objslam_detector.colors import ColorGate, classify, derive_gates
from objslam_detector.config import DetectorConfig
from objslam_detector.images import as_color_image, check_size
from objslam_detector.measure import measure
from objslam_detector.panorama import Panorama

logger = logging.getLogger(__name__)

_PANORAMA_CACHE_SIZE = 4
# Another class's blob this close beside a blob means one hides part of the other.
_TOUCH_PX = 2
# Brightest level of the black border outside the image circle.
_BLACK = 8


class Detector:
    """Detects catalog classes in images of any camera model and mount.

    Holds no per-image state, only the remap tables of the calibrations seen (built once
    per calibration), so one instance serves a whole image stream.
    """

    def __init__(self, config: DetectorConfig | None = None, catalog: Catalog | None = None) -> None:
        self.config = config or DetectorConfig()
        self.catalog = catalog if catalog is not None else load_catalog(self.config.catalog_file or None)
        try:
            self.gates: tuple[ColorGate, ...] = derive_gates(self.catalog, self.config.color)
        except ValueError as exc:
            raise ConfigError(str(exc)) from exc
        self._panoramas: OrderedDict[CameraModel, tuple[Panorama, Segmenter]] = OrderedDict()

    def panorama(self, camera: CameraModel) -> Panorama:
        """Remap tables of a calibration, built on first use."""
        return self._for_camera(camera)[0]

    def view(self, camera: CameraModel) -> CameraModel:
        """The camera seen from its level frame (the mount's roll and pitch applied): the
        frame the slices are measured in, and the model to draw them on the image with."""
        mount = self.config.camera_mount
        return level_view(camera, mount.roll_rad, mount.pitch_rad)

    def detect(self, image: NDArray, camera: CameraModel, encoding: str = "rgb8") -> list[SliceMeasurement]:
        """Slices of one image, in no particular order.

        ``image`` is (H, W, C) or (H, W) uint8 in ``encoding`` (rgb8, bgr8, rgba8, bgra8,
        mono8) and must match the calibration's size; DetectorInputError otherwise.
        """
        pano, segmenter = self._for_camera(camera)
        rgb = self.unwarp(image, camera, encoding)
        class_index = self.class_index(rgb)
        blobs = segmenter.blobs(class_index)
        slices = []
        for blob in blobs:
            cuts = _view_cuts(blob, pano, rgb)
            truncated = blob.cut or _beside_other_class(blob, class_index) or cuts != 0
            label = self.gates[blob.class_index - 1].label
            slices.append(
                measure(
                    blob,
                    label,
                    rgb,
                    pano,
                    truncated,
                    truncated_confidence=self.config.blobs.truncated_confidence,
                    cut_edges=cuts,
                )
            )
        return slices

    def unwarp(self, image: NDArray, camera: CameraModel, encoding: str = "rgb8") -> NDArray[np.uint8]:
        """The checked image as an RGB panorama (rows: elevation, columns: azimuth)."""
        color = as_color_image(image, encoding)
        check_size(color.pixels, camera)
        pano = self.panorama(camera).unwarp(color.pixels)
        return pano if color.order == "rgb" else cv2.cvtColor(pano, cv2.COLOR_BGR2RGB)

    def class_index(self, rgb_panorama: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """Cleaned class index of an RGB panorama: 0 none, k + 1 for ``self.gates[k]``."""
        index = classify(cv2.cvtColor(rgb_panorama, cv2.COLOR_RGB2HSV_FULL), self.gates)
        return clean(index, self.config.blobs.opening_kernel_px)

    def _for_camera(self, camera: CameraModel) -> tuple[Panorama, Segmenter]:
        entry = self._panoramas.get(camera)
        if entry is None:
            pano = Panorama.build(self.view(camera), self.config.panorama)
            logger.debug("panorama %dx%d px for %s", pano.cols, pano.rows, camera)
            horizon_row = float(pano.row_of_elevation(0.0))
            entry = (pano, Segmenter(self.config.blobs, pano.azimuth_step_rad, pano.elevation_step_rad, horizon_row))
            self._panoramas[camera] = entry
            while len(self._panoramas) > _PANORAMA_CACHE_SIZE:
                self._panoramas.popitem(last=False)
        else:
            self._panoramas.move_to_end(camera)
        return entry


def _beside_other_class(blob: Blob, class_index: NDArray[np.uint8]) -> bool:
    """Another class's pixels right left or right of the blob: one object partly hides the other."""
    rows = slice(max(blob.row0 - _TOUCH_PX, 0), blob.row0 + blob.rows + _TOUCH_PX)
    sides = np.concatenate(
        [
            strip(class_index, rows, blob.col0 - _TOUCH_PX, blob.col0),
            strip(class_index, rows, blob.col0 + blob.cols, blob.col0 + blob.cols + _TOUCH_PX),
        ],
        axis=1,
    )
    return bool(np.any((sides != 0) & (sides != blob.class_index)))


def _view_cuts(blob: Blob, pano: Panorama, rgb_panorama: NDArray[np.uint8]) -> int:
    """The blob's edges the view cut off, as ``CUT_*`` bits: it reaches the panorama's top or
    bottom, or the part outside the image or its dark border right above, below, left or right.

    Mirror cameras (and renderers) leave the image black outside a circle that may lie
    inside the image rectangle, so black right above or below a blob also means the
    view cut it. A perspective or fisheye camera's view ends left and right too.
    """
    body = slice(blob.row0, blob.row0 + blob.rows)
    left, right = blob.col0 + blob.cols, blob.col0  # columns grow with azimuth: left is the far side
    cuts = 0
    for bit, row, at_edge in (
        (CUT_TOP, blob.row0 - 1, blob.row0 == 0),
        (CUT_BOTTOM, blob.row0 + blob.rows, blob.row0 + blob.rows >= pano.rows),
    ):
        if at_edge:
            cuts |= bit
            continue
        rows = slice(row, row + 1)
        cols = (blob.col0, blob.col0 + blob.cols)
        if not strip(pano.inside, rows, *cols).all() or np.any(strip(rgb_panorama, rows, *cols).max(axis=-1) <= _BLACK):
            cuts |= bit
    if not isinstance(pano.camera, UnifiedCamera):
        if not strip(pano.inside, body, left, left + 1).all():
            cuts |= CUT_LEFT
        if not strip(pano.inside, body, right - 1, right).all():
            cuts |= CUT_RIGHT
    return cuts
