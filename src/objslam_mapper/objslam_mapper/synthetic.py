"""Synthetic runs drawn from the mapper's own model, for tests and benchmarks.

A run is a true trajectory and scene; odometry is the true motion plus noise drawn from
the odometry noise model, and every object in range gives one slice per image, predicted
by :mod:`slice_model` plus noise drawn from the slice noise model. Noise scales of 0
give exact data. This is not the image simulator (``objslam sim``): no pixels, no
detector, no distractors; it knows the measurement-to-object truth, which is what the
solver and sampler tests need.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from objslam_common.catalog import Catalog, load_catalog
from objslam_common.geometry import between, compose, wrap_angle
from objslam_common.mount import CameraMount
from objslam_common.records import ImageSlices, OdometrySample, SliceMeasurement
from objslam_mapper.config import GraphConfig
from objslam_mapper.graph.problem import GraphProblem, class_measurement_stddev
from objslam_mapper.model.odometry import increment_stddev, poses_at_stamps
from objslam_mapper.model.slice_model import predict_slices


@dataclass(frozen=True)
class SyntheticObject:
    label: str
    location_m: tuple[float, float, float]  # x, y, z_base
    size_m: tuple[float, float]  # diameter, height


@dataclass(frozen=True, eq=False)
class SyntheticRun:
    """Inputs of the mapper plus the truth behind them."""

    odometry: tuple[OdometrySample, ...]
    images: tuple[ImageSlices, ...]
    true_map_T_base: NDArray[np.float64]  # (N, 3) at the image stamps
    objects: tuple[SyntheticObject, ...]
    slice_object: tuple[tuple[int, ...], ...]  # per image, the object number of each slice

    def groups(self, problem: GraphProblem) -> list[list[int]]:
        """The true association as groups of the problem's measurement indices (objects seen)."""
        groups: list[list[int]] = [[] for _ in self.objects]
        for m, (image, slot) in enumerate(zip(problem.measurement_image, problem.measurement_slot, strict=True)):
            groups[self.slice_object[image][slot]].append(m)
        return [g for g in groups if g]

    def seen_objects(self) -> list[int]:
        """Object numbers in the order of :meth:`groups`."""
        seen = {j for per_image in self.slice_object for j in per_image}
        return sorted(seen)


def ellipse_trajectory(count: int, semi_axes_m: tuple[float, float] = (3.0, 2.0), laps: float = 1.0) -> NDArray:
    """(count, 3) poses driving counter-clockwise around an ellipse centred at the origin, facing forward."""
    t = np.linspace(0.0, 2.0 * np.pi * laps, count)
    a, b = semi_axes_m
    heading = np.arctan2(b * np.cos(t), -a * np.sin(t))
    return np.stack([a * np.cos(t), b * np.sin(t), wrap_angle(heading)], axis=-1)


def office_scene() -> tuple[SyntheticObject, ...]:
    """Twelve objects of the default catalog's classes around an 8 x 6 m room."""
    specs = [
        ("red", (4.2, 0.5, 0.0), (0.30, 0.60)),
        ("red", (-1.0, 3.1, 0.0), (0.32, 0.58)),
        ("green", (1.5, -3.2, 0.0), (0.40, 0.40)),
        ("green", (-4.1, -1.0, 0.0), (0.38, 0.42)),
        ("blue", (0.0, 0.0, 0.0), (0.20, 0.90)),
        ("blue", (2.8, 2.9, 0.0), (0.21, 0.88)),
        ("yellow", (-2.9, -2.8, 0.0), (0.50, 0.30)),
        ("yellow", (4.0, -2.0, 0.0), (0.48, 0.31)),
        ("cyan", (-3.6, 2.2, 0.75), (0.15, 0.25)),
        ("cyan", (1.8, 1.0, 0.75), (0.14, 0.26)),
        ("red", (-1.8, -0.6, 0.0), (0.29, 0.62)),
        ("green", (3.3, -0.4, 0.0), (0.41, 0.39)),
    ]
    return tuple(SyntheticObject(label, loc, size) for label, loc, size in specs)


def _samples(stamps_ns: Sequence[int], poses: Sequence[NDArray] | NDArray) -> tuple[OdometrySample, ...]:
    return tuple(OdometrySample(s, *map(float, p[:3])) for s, p in zip(stamps_ns, poses, strict=True))


def simulate_run(
    true_poses: NDArray[np.float64],
    stamps_ns: Sequence[int],
    objects: Sequence[SyntheticObject],
    catalog: Catalog,
    rng: np.random.Generator,
    *,
    config: GraphConfig | None = None,
    mount: CameraMount | None = None,
    image_stamps_ns: Sequence[int] | None = None,
    odometry_noise_scale: float = 1.0,
    slice_noise_scale: float = 1.0,
    range_limits_m: tuple[float, float] = (0.5, 5.0),
    odometry_calibration: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> SyntheticRun:
    """Odometry at ``stamps_ns`` (true poses ``true_poses``) and slices at ``image_stamps_ns``.

    Images default to the odometry stamps. Image poses are the true poses interpolated
    like the mapper does, so an exact run is exactly consistent with the model.
    ``odometry_calibration`` = (distance scale, turn scale, turn bias rad/m) is a systematic
    odometry error, applied to each true increment as the graph models it
    (:mod:`objslam_mapper.graph.linearize`) before the random noise.
    """
    config = config or GraphConfig()
    mount = mount or config.camera_mount.to_mount()
    true_poses = np.asarray(true_poses, dtype=float)
    stamps = [int(s) for s in stamps_ns]
    image_stamps = stamps if image_stamps_ns is None else [int(s) for s in image_stamps_ns]

    # Odometry: true increments plus random-walk noise of the model, chained from the true start.
    increments = [between(a, b) for a, b in itertools.pairwise(true_poses)]
    odometry_poses = [true_poses[0]]
    distance_scale, turn_scale, turn_bias = odometry_calibration
    for inc in increments:
        if any(odometry_calibration):
            length = float(np.hypot(inc[0], inc[1]))
            inc = np.r_[(1.0 + distance_scale) * inc[:2], (1.0 + turn_scale) * inc[2] + turn_bias * length]
        sd = increment_stddev(np.hypot(inc[0], inc[1]), abs(inc[2]), config.odometry)
        noisy = inc + odometry_noise_scale * sd * rng.standard_normal(3)
        odometry_poses.append(compose(odometry_poses[-1], noisy))
    odometry = _samples(stamps, odometry_poses)

    at = poses_at_stamps(_samples(stamps, true_poses), image_stamps)
    image_stamps = [s for s, ok in zip(image_stamps, at.accepted, strict=True) if ok]
    image_poses = at.poses

    loc = np.array([o.location_m for o in objects], dtype=float).reshape(-1, 3)
    size = np.array([o.size_m for o in objects], dtype=float).reshape(-1, 2)
    stddev = np.array([class_measurement_stddev(catalog[o.label], config.slice_noise, mount) for o in objects]).reshape(
        -1, 4
    )
    images, slice_object = [], []
    for stamp, pose in zip(image_stamps, image_poses, strict=True):
        pred = predict_slices(pose[None, :], loc, size, mount, jacobians=False)
        seen = np.flatnonzero(pred.valid & (pred.range_m >= range_limits_m[0]) & (pred.range_m <= range_limits_m[1]))
        values = pred.values[seen] + slice_noise_scale * stddev[seen] * rng.standard_normal((len(seen), 4))
        slices = []
        for j, (bearing, width, bottom, top) in zip(seen, values, strict=True):
            slices.append(
                SliceMeasurement(
                    label=objects[int(j)].label,
                    confidence=1.0,
                    bearing_rad=float(wrap_angle(bearing)),
                    angular_width_rad=float(max(width, 1e-4)),
                    # Noise may cross the edges; the lower edge (the noisier one for raised
                    # objects) gives way so the top stays as drawn.
                    elevation_bottom_rad=float(min(bottom, top)),
                    elevation_top_rad=float(top),
                )
            )
        images.append(ImageSlices(stamp, tuple(slices)))
        slice_object.append(tuple(int(j) for j in seen))
    return SyntheticRun(
        odometry=odometry,
        images=tuple(images),
        true_map_T_base=image_poses,
        objects=tuple(objects),
        slice_object=tuple(slice_object),
    )


def office_run(seed: int = 0, n_poses: int = 400, catalog: Catalog | None = None) -> SyntheticRun:
    """The benchmark run: 1.5 laps of a 6 x 4 m ellipse through :func:`office_scene`, 5 images/s.

    With the default catalog and noise it holds about 3000 slices of 12 objects.
    """
    poses = ellipse_trajectory(n_poses, (3.0, 2.0), laps=1.5)
    stamps = [k * 200_000_000 for k in range(n_poses)]
    return simulate_run(poses, stamps, office_scene(), catalog or load_catalog(), np.random.default_rng(seed))
