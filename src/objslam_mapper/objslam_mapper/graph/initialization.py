"""A first guess of an object from its measurements, to start the solver from.

Each slice gives the object's axis along its bearing ray at a range inferred from the
class prior (paper section 2: apparent size yields range even from one sighting):

- from the angular width, ``D = r / sin(width / 2)`` with the prior radius;
- from an elevation edge whose face lies clearly below or above the camera, with the
  prior base height and size: ``rho = (z_face - h) / tan(elevation)`` is the distance of
  the extreme rim, ``D = rho -+ r`` (near rim / far rim, see :mod:`slice_model`).

The ranges are fused by inverse variance (first order), each slice becomes a 2D Gaussian
guess of the axis (tight across its ray, loose along it), and the guesses are fused in
information form, which triangulates when the object was seen from several places. Base
height and size start at the class prior.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.model.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, WIDTH, camera_positions

_MIN_ELEVATION_RAD = 0.01  # an edge nearer the horizon says little about range
_MIN_FACE_OFFSET_M = 0.05  # a face this close to the camera height says little about range


def _range_from_edge(
    face_m: float,
    face_var: float,
    radius: float,
    radius_var: float,
    elevation: NDArray,
    elevation_var: NDArray,
    *,
    far: bool,
) -> tuple[NDArray, NDArray]:
    """Range and variance from one edge; NaN/inf where the edge is not informative."""
    usable = (np.abs(face_m) > _MIN_FACE_OFFSET_M) & (np.sign(elevation) == np.sign(face_m))
    usable &= np.abs(elevation) > _MIN_ELEVATION_RAD
    tan_e = np.where(usable, np.tan(elevation), 1.0)
    sin_e = np.where(usable, np.sin(elevation), 1.0)
    rho = face_m / tan_e
    dist = rho + (-radius if far else radius)
    var = (face_m / sin_e**2) ** 2 * elevation_var + face_var / tan_e**2 + radius_var
    return np.where(usable, dist, np.nan), np.where(usable, var, np.inf)


def initial_object(problem: GraphProblem, indices: ArrayLike, map_T_base: NDArray[np.float64]) -> NDArray[np.float64]:
    """Starting (x, y, z_base, diameter, height) of an object seen by ``indices``."""
    idx = np.asarray(indices, dtype=np.int64)
    label = int(problem.measurement_label[idx[0]])
    mean, sd = problem.prior_mean[label], problem.prior_stddev[label]
    z_base, diameter, height = mean[2], mean[3], mean[4]
    radius, radius_var = 0.5 * diameter, (0.5 * sd[3]) ** 2
    mount = problem.mounts(idx)

    pose = np.asarray(map_T_base, dtype=float)[problem.measurement_pose[idx]]
    cam_x, cam_y = camera_positions(pose, mount)
    z = problem.measurements[idx]
    var = problem.measurement_stddev[idx] ** 2

    half = 0.5 * np.clip(z[:, WIDTH], 1e-4, np.pi - 1e-3)
    ranges = [radius / np.sin(half)]
    range_vars = [
        (ranges[0] * sd[3] / diameter) ** 2 + (radius * np.cos(half) / (2.0 * np.sin(half) ** 2)) ** 2 * var[:, WIDTH]
    ]
    bottom = z_base - mount.height_m
    top = z_base + height - mount.height_m
    for face, face_var, comp, far in (
        (bottom, sd[2] ** 2, ELEVATION_BOTTOM, bottom > 0.0),
        (top, sd[2] ** 2 + sd[4] ** 2, ELEVATION_TOP, top < 0.0),
    ):
        dist, dist_var = _range_from_edge(face, face_var, radius, radius_var, z[:, comp], var[:, comp], far=far)
        ranges.append(dist)
        range_vars.append(dist_var)
    weights = 1.0 / np.stack(range_vars)
    fused_var = 1.0 / np.sum(weights, axis=0)
    fused = fused_var * np.nansum(weights * np.stack(ranges), axis=0)
    fused = np.maximum(fused, 1.05 * radius)

    azimuth = z[:, BEARING] + pose[:, 2] + mount.yaw_rad
    ux, uy = np.cos(azimuth), np.sin(azimuth)
    guess = np.stack([cam_x + fused * ux, cam_y + fused * uy], axis=-1)
    along = 1.0 / fused_var
    across = 1.0 / (fused**2 * var[:, BEARING])
    u = np.stack([ux, uy], axis=-1)
    n = np.stack([-uy, ux], axis=-1)
    info = along[:, None, None] * u[:, :, None] * u[:, None, :] + across[:, None, None] * n[:, :, None] * n[:, None, :]
    info_sum = info.sum(axis=0)
    xy = np.linalg.solve(info_sum, np.einsum("kij,kj->i", info, guess))
    return np.array([xy[0], xy[1], z_base, diameter, height])
