"""The small simulated scene the factor-graph tests share: five objects, one of each class."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from objslam_common.catalog import load_catalog
from objslam_common.geometry import rotation, transform_points
from objslam_mapper.config import GraphConfig
from objslam_mapper.graph.solver import GraphSolution, ObjectEstimate
from objslam_mapper.synthetic import SyntheticObject, SyntheticRun
from objslam_tools.trajectory import fit_se2

CATALOG = load_catalog()
CONFIG = GraphConfig()
MOUNT = CONFIG.camera_mount.to_mount()
STEP_NS = 250_000_000
SCENE = (
    SyntheticObject("red", (2.2, 0.3, 0.0), (0.31, 0.58)),
    SyntheticObject("green", (-0.5, 1.0, 0.0), (0.41, 0.39)),
    SyntheticObject("cyan", (0.4, -0.9, 0.75), (0.15, 0.26)),
    SyntheticObject("blue", (-2.0, -0.5, 0.0), (0.2, 0.92)),
    SyntheticObject("yellow", (0.5, 2.4, 0.0), (0.5, 0.3)),
)


def draw_scene(rng: np.random.Generator, floor_z_base_spread_m: float | None = None) -> tuple[SyntheticObject, ...]:
    """SCENE with base heights and sizes drawn from the class priors (for consistency tests).

    ``floor_z_base_spread_m``: floor objects' base heights drawn with this stddev instead
    of their prior's (0: on the floor, as in the bags).
    """
    objects = []
    for obj in SCENE:
        cls = CATALOG[obj.label]
        size = rng.normal(cls.size_mean, [cls.diameter_stddev_m, cls.height_stddev_m])
        spread = cls.z_base_stddev_m if floor_z_base_spread_m is None or not cls.on_floor else floor_z_base_spread_m
        z_base = rng.normal(cls.z_base_m, spread)
        objects.append(SyntheticObject(obj.label, (obj.location_m[0], obj.location_m[1], z_base), tuple(size)))
    return tuple(objects)


def object_nees(
    solution: GraphSolution, run: SyntheticRun, covariance_of: Callable[[ObjectEstimate], np.ndarray]
) -> list[float]:
    """NEES (x, y, z_base) of each seen object, its error measured after fitting the trajectory as objslam eval does."""
    gt_T_map = fit_se2(solution.map_T_base[:, :2], run.true_map_T_base[:, :2])
    rotate = np.eye(3)
    rotate[:2, :2] = rotation(gt_T_map[2])
    nees = []
    for j, obj in zip(run.seen_objects(), solution.objects, strict=True):
        location = np.r_[transform_points(gt_T_map, obj.location_m[None, :2])[0], obj.location_m[2]]
        error = location - np.array(run.objects[j].location_m)
        nees.append(float(error @ np.linalg.solve(rotate @ covariance_of(obj) @ rotate.T, error)))
    return nees
