"""Which real objects the camera saw: the denominator of "recall of seen objects".

A forward-looking camera may never see some objects of a room; missing those is not the
mapper's fault. An object counts as **seen** when, in at least ``MIN_IMAGES`` images of the
bag, its whole silhouette lies in the image (:func:`objslam_tools.silhouette.visible_objects`,
from ``/ground_truth/odom`` at the image stamps, with the bag's camera and the ground truth's
mount), at most half of it is hidden by nearer things, and it is at least ``MIN_WIDTH_PX``
pixels wide (the detector's blobs need a few columns).
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from objslam_tools.bag import Bag
from objslam_tools.ground_truth import GroundTruth
from objslam_tools.silhouette import visible_objects
from objslam_tools.trajectory import PoseTrack

MIN_IMAGES = 10
MAX_HIDDEN_FRACTION = 0.5
MIN_WIDTH_PX = 6.0


def images_seen(bag: Bag, truth: GroundTruth, track: PoseTrack) -> dict[int, int]:
    """For every real object, the number of the bag's images that saw it (module docstring)."""
    view = truth.mount.level_view(bag.read_camera())
    stamps = np.array([raw.stamp_ns for raw in bag.raw_messages([bag.image_topic()])], dtype=np.int64)
    stamps = stamps[track.covers(stamps)] if len(stamps) else stamps
    counts: Counter[int] = Counter({o.id: 0 for o in truth.objects})
    if len(stamps) == 0:
        return dict(counts)
    for pose in track.interpolate(stamps):
        for seen in visible_objects(truth, pose, view):
            if seen.in_view and seen.occluded_fraction <= MAX_HIDDEN_FRACTION and seen.width_px >= MIN_WIDTH_PX:
                counts[seen.object_id] += 1
    return dict(counts)


def seen_ids(counts: dict[int, int], min_images: int = MIN_IMAGES) -> frozenset[int]:
    """The objects seen in at least ``min_images`` images."""
    return frozenset(i for i, n in counts.items() if n >= min_images)
