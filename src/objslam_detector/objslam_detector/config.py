"""Settings of the detector (ROS parameters of the ``detector`` node, config/detector.yaml)."""

from __future__ import annotations

from dataclasses import dataclass

from objslam_common.config import setting
from objslam_common.mount import CameraMountConfig
from objslam_detector.colors import parse_class_overrides


@dataclass(frozen=True)
class PanoramaConfig:
    """The azimuth x elevation image the omnidirectional image is unwarped into."""

    azimuth_resolution_deg: float = setting(
        0.3, "panorama column width, deg (about the camera's own resolution at the horizon)", minimum=0.05, maximum=2.0
    )
    elevation_resolution_deg: float = setting(0.3, "panorama row height, deg", minimum=0.05, maximum=2.0)
    min_elevation_deg: float = setting(
        -80.0, "lowest elevation unwarped, deg (straight down is -90)", minimum=-89.5, maximum=0.0
    )
    max_elevation_deg: float = setting(
        60.0, "highest elevation unwarped, deg; clipped to what the camera sees", minimum=0.0, maximum=89.0
    )


@dataclass(frozen=True)
class ColorConfig:
    """Colour gates in HSV, derived from the catalog colours.

    Hue and saturation follow the surface colour under white light of any strength,
    so the gates test hue (around the class hue) and a floor on saturation and value.
    """

    hue_halfwidth_max_deg: float = setting(
        20.0,
        "largest hue half-width of a class gate, deg",
        minimum=1.0,
        maximum=90.0,
        expert=True,
    )
    hue_neighbor_fraction: float = setting(
        0.45,
        "a gate reaches at most this fraction of the way to the nearest other class hue (< 0.5: gates never overlap)",
        minimum=0.05,
        maximum=0.5,
        expert=True,
    )
    min_saturation_fraction: float = setting(
        0.45,
        "saturation floor as a fraction of the class colour's saturation",
        minimum=0.0,
        maximum=1.0,
        expert=True,
    )
    min_saturation: float = setting(
        0.2, "absolute saturation floor (0..1), rejects greys", minimum=0.0, maximum=1.0, expert=True
    )
    min_value: float = setting(
        0.1,
        "brightness floor (0..1): hue is noise in very dark pixels",
        minimum=0.0,
        maximum=1.0,
        expert=True,
    )
    class_overrides: tuple[str, ...] = setting(
        (),
        "per-class gate overrides, each 'LABEL: key=value, ...' with keys hue_deg, hue_halfwidth_deg, "
        "min_saturation, min_value (e.g. 'red: hue_halfwidth_deg=12, min_saturation=0.5')",
    )

    def __post_init__(self) -> None:
        parse_class_overrides(self.class_overrides)  # fail at load time, naming the bad entry


@dataclass(frozen=True)
class BlobConfig:
    """Cleaning the colour masks and gating the blobs."""

    opening_kernel_px: int = setting(3, "square opening kernel against speckle, panorama px (1 = off)", minimum=1)
    min_pixel_count: int = setting(40, "fewest panorama pixels of a blob", minimum=1)
    min_angular_width_deg: float = setting(1.0, "narrowest blob, deg of azimuth", minimum=0.0)
    min_angular_height_deg: float = setting(1.0, "lowest blob, deg of elevation", minimum=0.0)
    max_angular_width_deg: float = setting(120.0, "widest blob, deg of azimuth", minimum=1.0, maximum=360.0)
    min_fill_ratio: float = setting(
        0.3, "fewest blob pixels per pixel of its bounding box (cylinders are nearly full)", minimum=0.0, maximum=1.0
    )
    separate_same_class: bool = setting(
        True, "split blobs where one object of a class partly hides another of the same class"
    )
    truncated_confidence: float = setting(
        0.5,
        "confidence of a slice that touches another class's blob or the edge of the view (likely cut short)",
        minimum=0.0,
        maximum=1.0,
    )


IMAGE_TRANSPORTS = ("auto", "raw", "compressed")


@dataclass(frozen=True)
class DetectorConfig:
    """Everything the detector library and node need."""

    catalog_file: str = setting("", "class catalog file; empty = the bundled config/catalog.yaml")
    image_topic: str = setting("/camera/image_raw", "raw image topic (sensor_msgs/Image)")
    image_transport: str = setting(
        "auto",
        "auto (whichever of IMAGE_TOPIC and IMAGE_TOPIC/compressed brings images first), "
        "raw (sensor_msgs/Image) or compressed (sensor_msgs/CompressedImage on IMAGE_TOPIC/compressed)",
    )
    camera_info_topic: str = setting(
        "/camera/camera_info",
        "calibration topic (sensor_msgs/CameraInfo: unified, plumb_bob, rational_polynomial or equidistant)",
    )
    camera_mount: CameraMountConfig = setting(
        CameraMountConfig(),
        "camera mount on the robot, the same as the mapper's (the detector uses its roll and pitch)",
    )
    publish_debug_image: bool = setting(False, "publish the image with the slices drawn on it")
    reliable_images: bool = setting(
        False,
        "subscribe to images with reliable QoS (no frame lost from a played bag) instead of sensor-data best effort",
    )
    # Frozen nested defaults are immutable, so sharing one instance is safe.
    panorama: PanoramaConfig = setting(PanoramaConfig(), "unwarping", expert=True)
    color: ColorConfig = setting(ColorConfig(), "colour gates")
    blobs: BlobConfig = setting(BlobConfig(), "mask cleaning and blob gates", expert=True)

    def __post_init__(self) -> None:
        if self.image_transport not in IMAGE_TRANSPORTS:
            raise ValueError(
                f"image_transport must be one of {', '.join(IMAGE_TRANSPORTS)}, got {self.image_transport!r}"
            )
