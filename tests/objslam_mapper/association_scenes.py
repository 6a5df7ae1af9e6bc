"""Small synthetic scenes for the association tests, drawn from the graph's own slice model.

The robot drives 6 m out along x, turns on the spot and drives back; with a 3.5 m range
limit objects near the start are seen on the way out and again on the way back, so each
gives two tracklets that only the sampler can join. Two red objects stand 0.8 m apart.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from objslam_common.catalog import load_catalog
from objslam_common.geometry import wrap_angle
from objslam_common.records import ImageSlices, SliceMeasurement
from objslam_mapper.config import GraphConfig
from objslam_mapper.graph.problem import GraphProblem, build_problem
from objslam_mapper.synthetic import SyntheticObject, SyntheticRun, simulate_run

RED_A = SyntheticObject("red", (1.5, 1.2, 0.0), (0.30, 0.60))
RED_B = SyntheticObject("red", (1.5, 2.0, 0.0), (0.31, 0.59))  # 0.8 m from RED_A
GREEN = SyntheticObject("green", (4.5, -1.3, 0.0), (0.40, 0.40))
POSTER_FRAMES = range(8, 12)


def out_and_back_poses() -> np.ndarray:
    out = np.column_stack([np.linspace(0.0, 6.0, 31), np.zeros(31), np.zeros(31)])
    turn = np.column_stack([np.full(8, 6.0), np.zeros(8), np.linspace(0.0, np.pi, 10)[1:-1]])
    back = np.column_stack([np.linspace(6.0, 0.0, 31), np.zeros(31), np.full(31, np.pi)])
    return np.vstack([out, turn, back])


def simulate(objects: Sequence[SyntheticObject] = (RED_A, RED_B, GREEN), seed: int = 0) -> SyntheticRun:
    poses = out_and_back_poses()
    stamps = [k * 200_000_000 for k in range(len(poses))]
    return simulate_run(poses, stamps, objects, load_catalog(), np.random.default_rng(seed), range_limits_m=(0.5, 3.5))


def with_poster(run: SyntheticRun, label: str = "green") -> list[ImageSlices]:
    """The run's images plus slices of a flat poster on the wall y = -2.5 (x 2.7..3.3 m,
    1.0..1.4 m above the floor) in four consecutive images: a consistent distractor that
    no floor object of its class can explain."""
    mount = GraphConfig().camera_mount.to_mount()
    images = list(run.images)
    for k in POSTER_FRAMES:
        cam = mount.camera_pose(run.true_map_T_base[k])
        edges = [wrap_angle(np.arctan2(-2.5 - cam[1], x - cam[0]) - cam[2]) for x in (2.7, 3.3)]
        distance = np.hypot(3.0 - cam[0], -2.5 - cam[1])
        poster = SliceMeasurement(
            label=label,
            confidence=1.0,
            bearing_rad=float(wrap_angle(edges[0] + 0.5 * wrap_angle(edges[1] - edges[0]))),
            angular_width_rad=float(abs(wrap_angle(edges[1] - edges[0]))),
            elevation_bottom_rad=float(np.arctan2(1.0 - mount.height_m, distance)),
            elevation_top_rad=float(np.arctan2(1.4 - mount.height_m, distance)),
        )
        images[k] = ImageSlices(images[k].stamp_ns, (*images[k].slices, poster))
    return images


def problem_of(run: SyntheticRun, images: Sequence[ImageSlices] | None = None) -> GraphProblem:
    config = GraphConfig()
    return build_problem(
        run.odometry, run.images if images is None else images, config.camera_mount.to_mount(), load_catalog(), config
    )
