"""A small simulated scene for evaluation and figure tests: bag + ground_truth.yaml + a perfect map."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from objslam_common.cameras.unified import UnifiedCamera
from objslam_common.catalog import load_catalog
from objslam_common.geometry import wrap_angle
from objslam_common.mount import CameraMount
from objslam_mapper.map_file import BuiltMap, MappedObject, TrajectoryPose
from objslam_mapper.model.slice_model import predict_slices
from objslam_tools.ground_truth import Distractor, GroundTruth, GroundTruthObject, write_ground_truth
from objslam_tools.trajectory import transform_poses
from tests.objslam_tools.synthetic_bag import camera_info_msg, image_msg, odometry_records, write_bag

S = 1_000_000_000
# The map's odom frame seen from the ground-truth frame: what alignment must recover.
GT_T_ODOM = np.array([3.0, -1.5, 0.7])

OBJECTS = (
    GroundTruthObject(0, "red", (2.0, 1.0, 0.0), (0.31, 0.62)),
    GroundTruthObject(1, "red", (4.5, 3.0, 0.0), (0.29, 0.58)),
    GroundTruthObject(2, "green", (1.0, 4.0, 0.0), (0.41, 0.39)),
    GroundTruthObject(3, "blue", (5.0, 0.5, 0.0), (0.2, 0.9)),
    GroundTruthObject(4, "cyan", (3.5, 5.0, 0.76), (0.15, 0.25)),
)
DISTRACTORS = (Distractor(0, "poster", "yellow", (220, 200, 30), (0.0, 2.0, 1.2), (0.6, 0.8), 0.0),)


def ground_truth_poses(n: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """A loop around the objects in the ground-truth frame; stamps 0.1 s apart."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    x = 3.0 + 2.2 * np.cos(t)
    y = 2.5 + 1.8 * np.sin(t)
    theta = np.arctan2(1.8 * np.cos(t), -2.2 * np.sin(t))
    stamps = (10 * S + np.arange(n) * (S // 10)).astype(np.int64)
    return stamps, np.column_stack([x, y, theta])


def drifting_odometry(poses: np.ndarray) -> np.ndarray:
    """Odometry with a heading drift, so its ATE is clearly above the map's."""
    drift = np.linspace(0.0, 0.25, len(poses))
    out = poses.copy()
    c = poses[0, :2]
    for i, a in enumerate(drift):
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        out[i, :2] = c + rot @ (poses[i, :2] - c)
        out[i, 2] += a
    return out


def render(camera: UnifiedCamera, map_T_base: np.ndarray, objects=OBJECTS, mount: CameraMount | None = None):
    """A crude omnidirectional image: each object's silhouette sector filled with its class colour."""
    mount = mount or CameraMount()
    catalog = load_catalog()
    v, u = np.mgrid[0 : camera.height_px, 0 : camera.width_px]
    az, el = camera.unproject(u + 0.0, v + 0.0)
    image = np.full((camera.height_px, camera.width_px, 3), 90, dtype=np.uint8)
    image[el > 0] = (170, 170, 180)  # walls and ceiling above the horizon
    pred = predict_slices(
        map_T_base, [o.position_m for o in objects], [o.size_m for o in objects], mount, jacobians=False
    )
    for k in np.argsort(-pred.range_m):  # far first, near objects paint over them
        bearing, width, bottom, top = pred.values[k]
        inside = (np.abs(wrap_angle(az - bearing)) <= width / 2) & (el >= bottom) & (el <= top)
        image[inside] = catalog[objects[k].label].color_rgb
    return image


CAMERA = UnifiedCamera(width_px=320, height_px=320, xi=0.9, fx=85.0, fy=85.0, cx=160.0, cy=160.0)


def write_scene_bag(directory: Path, storage: str = "mcap", images_every: int = 0) -> Path:
    """The scene's bag; with ``images_every`` > 0 also camera info and a rendered image every that many poses."""
    stamps, gt_poses = ground_truth_poses()
    odom_poses = transform_poses(_inverse(GT_T_ODOM), drifting_odometry(gt_poses))
    records = odometry_records("/ground_truth/odom", stamps, gt_poses, frame_id="world")
    records += odometry_records("/odom", stamps, odom_poses)
    if images_every:
        records.append(("/camera/camera_info", int(stamps[0]), camera_info_msg(int(stamps[0]), CAMERA)))
        for s, p in zip(stamps[::images_every], gt_poses[::images_every], strict=True):
            records.append(("/camera/image_raw", int(s), image_msg(int(s), render(CAMERA, p))))
    bag = write_bag(directory, records, storage=storage)
    write_ground_truth(bag, GroundTruth(objects=OBJECTS, distractors=DISTRACTORS))
    return bag


def _inverse(a_T_b: np.ndarray) -> np.ndarray:
    c, s = np.cos(a_T_b[2]), np.sin(a_T_b[2])
    xy = -np.array([[c, s], [-s, c]]) @ a_T_b[:2]
    return np.array([xy[0], xy[1], -a_T_b[2]])


def to_odom(position: tuple[float, float, float]) -> tuple[float, float, float]:
    xy = transform_poses(_inverse(GT_T_ODOM), [[position[0], position[1], 0.0]])[0, :2]
    return (float(xy[0]), float(xy[1]), float(position[2]))


def perfect_map(every: int = 2) -> BuiltMap:
    """The ground truth expressed in the odom frame; trajectory at every other ground-truth stamp."""
    stamps, gt_poses = ground_truth_poses()
    poses = transform_poses(_inverse(GT_T_ODOM), gt_poses)
    cov = ((0.01, 0.0, 0.0), (0.0, 0.02, 0.0), (0.0, 0.0, 0.0004))
    objects = tuple(
        MappedObject(
            id=10 + o.id,
            label=o.label,
            position_m=to_odom(o.position_m),
            size_m=o.size_m,
            existence_probability=0.9,
            position_covariance=cov,
            measurement_count=20,
        )
        for o in OBJECTS
    )
    trajectory = tuple(
        TrajectoryPose(int(s), float(p[0]), float(p[1]), float(p[2]))
        for s, p in zip(stamps[::every], poses[::every], strict=True)
    )
    return BuiltMap(objects=objects, trajectory=trajectory, diagnostics={"samples": 10})


def moved(built: BuiltMap, object_id: int, dx_gt_m: float) -> BuiltMap:
    """The map with one object moved by dx along the ground-truth x axis."""
    objects = []
    for o in built.objects:
        if o.id == object_id:
            step = transform_poses([0.0, 0.0, -GT_T_ODOM[2]], [[dx_gt_m, 0.0, 0.0]])[0, :2]
            o = replace(o, position_m=(o.position_m[0] + step[0], o.position_m[1] + step[1], o.position_m[2]))
        objects.append(o)
    return replace(built, objects=tuple(objects))
