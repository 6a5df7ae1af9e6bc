"""Render a scenario and write it as a rosbag2 bag (MCAP) per the data contract.

The bag is written into a hidden staging directory beside the target and renamed into
place only when complete, so an interrupted run never leaves a half bag under the name
the user asked for.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from objslam_common.cameras import UnifiedCamera
from objslam_common.mount import CameraMount
from objslam_tools.errors import UserError
from objslam_tools.ground_truth import write_ground_truth
from objslam_tools.sim import messages
from objslam_tools.sim.motion import increments
from objslam_tools.sim.render import renderer_for
from objslam_tools.sim.scenarios import GROUND_TRUTH_FRAME, ODOM_RATE_HZ, Scenario, render_rng

logger = logging.getLogger(__name__)

IMAGE_TOPIC = "/camera/image_raw"
COMPRESSED_TOPIC = "/camera/image_raw/compressed"
CAMERA_INFO_TOPIC = "/camera/camera_info"
ODOM_TOPIC = "/odom"
GROUND_TRUTH_TOPIC = "/ground_truth/odom"
TF_STATIC_TOPIC = "/tf_static"
IMAGE_FORMATS = ("jpeg", "png")
DEFAULT_JPEG_QUALITY = 90

Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class BagSummary:
    path: Path
    frames: int
    odom_messages: int
    render_seconds: float
    bytes_on_disk: int

    @property
    def seconds_per_frame(self) -> float:
        return self.render_seconds / max(1, self.frames)


def _velocities(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward speed and yaw rate over the interval ending at each pose (0 at the first)."""
    distance, turn = increments(poses)
    dt = 1.0 / ODOM_RATE_HZ
    return np.r_[0.0, distance / dt], np.r_[0.0, turn / dt]


def _odometry_variances(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Pose variances of /odom growing along the way, from the documented noise figures."""
    noise = scenario.odometry_noise
    distance, turn = increments(scenario.odom_poses)
    travelled = np.r_[0.0, np.cumsum(np.abs(distance))]
    turned = np.r_[0.0, np.cumsum(np.abs(turn))]
    xy_var = noise.distance_sigma_m_per_sqrt_m**2 * travelled + 1e-6
    yaw_var = noise.turn_sigma_rad_per_sqrt_rad**2 * turned + noise.turn_sigma_rad_per_sqrt_m**2 * travelled + 1e-6
    return xy_var, yaw_var


def _staging_root(out: Path) -> Path:
    """A hidden sibling of the target; the bag is built in ``<root>/<name>`` so its files get their final names."""
    return out.parent / f".{out.name}.partial-{os.getpid()}"


def write_bag(
    scenario: Scenario,
    out: str | os.PathLike[str],
    *,
    compressed: bool = False,
    image_format: str = "jpeg",
    jpeg_quality: int = DEFAULT_JPEG_QUALITY,
    progress: Progress | None = None,
) -> BagSummary:
    """Render every frame of ``scenario`` and write the bag directory ``out`` (which must not exist)."""
    out = Path(out)
    if out.exists():
        raise UserError(f"{out} already exists; refusing to overwrite it (choose another --out or remove it)")
    if image_format not in IMAGE_FORMATS:
        raise UserError(f"image format must be one of {', '.join(IMAGE_FORMATS)}, got {image_format!r}")
    if not 1 <= jpeg_quality <= 100:
        raise UserError(f"JPEG quality must be in 1..100, got {jpeg_quality}")
    root = _staging_root(out)
    staging = root / out.name
    try:
        if root.exists():
            shutil.rmtree(root)
        root.mkdir(parents=True)
        seconds = _write(scenario, staging, compressed, image_format, jpeg_quality, progress)
        write_ground_truth(staging, scenario.ground_truth())
        staging.rename(out)
    except OSError as exc:
        raise UserError(f"cannot write bag {out}: {exc.strerror or exc}") from exc
    finally:
        shutil.rmtree(root, ignore_errors=True)
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    return BagSummary(out, scenario.frames, len(scenario.odom_stamps_ns), seconds, size)


def carries_mount(scenario: Scenario) -> bool:
    """Whether the bag of ``scenario`` has /tf_static: every camera but the default omnidirectional
    one on the default mount."""
    return not isinstance(scenario.camera, UnifiedCamera) or scenario.mount != CameraMount()


def _write(
    scenario: Scenario, path: Path, compressed: bool, image_format: str, jpeg_quality: int, progress: Progress | None
) -> float:
    renderer = renderer_for(scenario.camera, scenario.mount)
    rng = render_rng(scenario)
    odom_speed, odom_rate = _velocities(scenario.odom_poses)
    true_speed, true_rate = _velocities(scenario.true_poses)
    xy_var, yaw_var = _odometry_variances(scenario)
    noise = scenario.odometry_noise
    twist_var = (noise.distance_sigma_m_per_sqrt_m**2 * ODOM_RATE_HZ, noise.turn_sigma_rad_per_sqrt_m**2 * ODOM_RATE_HZ)
    render_seconds = 0.0

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        ts = messages.TYPESTORE
        image_topic, image_type = (
            (COMPRESSED_TOPIC, messages.COMPRESSED_IMAGE) if compressed else (IMAGE_TOPIC, messages.IMAGE)
        )
        image_conn = writer.add_connection(image_topic, image_type, typestore=ts)
        info_conn = writer.add_connection(CAMERA_INFO_TOPIC, messages.CAMERA_INFO, typestore=ts)
        odom_conn = writer.add_connection(ODOM_TOPIC, messages.ODOMETRY, typestore=ts)
        truth_conn = writer.add_connection(GROUND_TRUTH_TOPIC, messages.ODOMETRY, typestore=ts)
        if carries_mount(scenario):
            # Forward-looking cameras' bags carry the mount (the data contract); the bundled
            # omnidirectional bags, on the default mount, stay as they were.
            tf_conn = writer.add_connection(TF_STATIC_TOPIC, messages.TF_MESSAGE, typestore=ts)
            first = int(min(scenario.image_stamps_ns[0], scenario.odom_stamps_ns[0]))
            writer.write(tf_conn, first, messages.serialize(messages.mount_transform(first, scenario.mount)))

        def write_odometry(j: int) -> None:
            stamp = int(scenario.odom_stamps_ns[j])
            odom = messages.odometry(
                stamp,
                messages.ODOM_FRAME,
                scenario.odom_poses[j],
                odom_speed[j],
                odom_rate[j],
                pose_variance=(xy_var[j], xy_var[j], yaw_var[j]),
                twist_variance=twist_var,
            )
            writer.write(odom_conn, stamp, messages.serialize(odom))
            truth = messages.odometry(stamp, GROUND_TRUTH_FRAME, scenario.true_poses[j], true_speed[j], true_rate[j])
            writer.write(truth_conn, stamp, messages.serialize(truth))

        j = 0
        total = scenario.frames
        for k in range(total):
            stamp = int(scenario.image_stamps_ns[k])
            while j < len(scenario.odom_stamps_ns) and scenario.odom_stamps_ns[j] <= stamp:
                write_odometry(j)
                j += 1
            started = time.perf_counter()
            rgb = renderer.render(scenario.scene, scenario.image_poses[k], rng).image_rgb
            if compressed:
                msg = messages.compressed_image(stamp, messages.encode(rgb, image_format, jpeg_quality), image_format)
            else:
                msg = messages.image(stamp, rgb)
            render_seconds += time.perf_counter() - started
            writer.write(image_conn, stamp, messages.serialize(msg))
            writer.write(info_conn, stamp, messages.serialize(messages.camera_info(stamp, scenario.camera)))
            if progress is not None:
                progress(k + 1, total)
        while j < len(scenario.odom_stamps_ns):
            write_odometry(j)
            j += 1
    logger.debug("wrote %s: %d frames, %.3f s per frame", path, total, render_seconds / total)
    return render_seconds
