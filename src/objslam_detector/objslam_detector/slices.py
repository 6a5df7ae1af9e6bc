"""The detector's output record: one slice (image sector around a colour blob)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DetectedSlice:
    """One detection, mirroring objslam_msgs/Slice.

    Angles are in the camera frame (azimuth counter-clockwise from the camera's forward
    axis, elevation above the horizontal); the ``*_px`` / ``angle_*`` fields describe the
    sector in the original omnidirectional image, for overlays.
    """

    label: str
    confidence: float
    bearing_rad: float
    angular_width_rad: float
    elevation_bottom_rad: float
    elevation_top_rad: float
    radius_inner_px: float
    radius_outer_px: float
    angle_start_rad: float
    angle_end_rad: float
    pixel_count: int
    # The blob touches another class's blob or the edge of the field of view, so its
    # extent is probably cut short (partial occlusion); its confidence is lowered.
    truncated: bool = False
