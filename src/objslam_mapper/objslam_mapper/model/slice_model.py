r"""Slice measurement model: what the camera sees of a vertical cylinder, with Jacobians.

An object is a solid vertical cylinder: axis at ``(x, y)``, base at height ``z_b``
(``location = (x, y, z_b)``), ``size = (d, H)`` (diameter, height), radius ``r = d/2``.
The camera sits at ``c = mount.camera_pose(map_T_base)`` at height ``h`` (docs/design.md, "Cameras and the mount").
With the horizontal vector ``delta = (x, y) - c_xy`` and its length ``D = |delta|``
(``D > r``: the camera is outside the object), the silhouette's extremes are:

bearing
    every point of the cylinder lies over its disc of radius r, so the silhouette's
    azimuth range is the one between the two tangents from the camera to that circle;
    it is symmetric about the axis: ``bearing = wrap(atan2(delta_y, delta_x) - yaw_cam)``.
angular width
    the tangents make half-angle ``asin(r/D)`` with the axis direction:
    ``width = 2 asin(r / D)``. (Not ``2 atan(r/D)``: the tangent points are nearer
    than the axis.)
elevation top
    the elevation of a point at horizontal distance ``rho`` and height ``z`` is
    ``atan2(z - h, rho)``: increasing in ``z``, so the maximum over the solid is on its
    top face ``z_t = z_b + H``; there ``rho`` ranges over ``[D - r, D + r]``. With
    ``a = z_t - h``: if ``a > 0`` (top above the camera) the maximum is at the smallest
    ``rho``: the NEAR rim of the top, ``atan2(a, D - r)``; if ``a < 0`` (top below the
    camera, looking down on it) it is at the largest ``rho``: the FAR rim of the top,
    ``atan2(a, D + r)``. (At ``a = 0`` both give 0.)
elevation bottom
    the minimum is on the base face, ``b = z_b - h``: if ``b < 0`` (base below the
    camera) the NEAR rim of the base, ``atan2(b, D - r)``; if ``b > 0`` (base above the
    camera, e.g. an object on a table seen by a 0.5 m high camera, looking up at its
    underside) the FAR rim of the base, ``atan2(b, D + r)``.

A model using the axis (``atan2(z - h, D)`` for both edges) is biased by up to
``atan(r/D)``-sized errors: low for tops seen from above, high for bases seen from below.

For objects on a support above the camera the support's top, wider than the object,
hides the object's lowest part, so the detector's lower edge is the support's near rim,
not the object's far base rim: :mod:`objslam_mapper.graph.problem` gives that component a wide
noise (``slice_noise.raised_elevation_bottom_stddev_rad``) instead of modelling tables.

Everything is vectorized over M measurements; the Jacobians are analytic, with respect to
the pose ``(x, y, theta)`` of base_link (additive coordinates), the location
``(x, y, z_b)`` and the size ``(d, H)``. The model is only defined for ``|r| < D``;
``valid`` flags the rest (their values are clamped, not meaningful).

The pose's ``x, y`` and the location's ``x, y`` enter only through ``delta``, so the 8
Jacobian columns reduce to 6: ``(delta_x, delta_y, theta, z_b, d, H)``
(:func:`predict_reduced`, ``d/d pose_xy = -d/d delta``, ``d/d location_xy = d/d delta``).
The solver works on that reduced, component-major form; :func:`predict_slices` expands it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import wrap_angle
from objslam_common.mount import CameraMount, CameraMounts
from objslam_common.records import CUT_BOTTOM, CUT_LEFT, CUT_RIGHT, CUT_TOP

BEARING, WIDTH, ELEVATION_BOTTOM, ELEVATION_TOP = range(4)
COMPONENTS = ("bearing", "angular_width", "elevation_bottom", "elevation_top")
REDUCED_COLUMNS = ("delta_x", "delta_y", "theta", "z_base", "diameter", "height")

_MAX_SINE = 1.0 - 1e-9  # clamp for r/D in invalid states, so nothing is NaN


@dataclass(frozen=True)
class SlicePrediction:
    """Predicted slices (M, 4) in the order of ``COMPONENTS``, and their Jacobians.

    ``d_pose`` (M, 4, 3), ``d_location`` (M, 4, 3), ``d_size`` (M, 4, 2) are None when
    not requested. ``range_m`` is the horizontal camera-to-axis distance D.
    """

    values: NDArray[np.float64]
    valid: NDArray[np.bool_]
    range_m: NDArray[np.float64]
    d_pose: NDArray[np.float64] | None = None
    d_location: NDArray[np.float64] | None = None
    d_size: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class ReducedPrediction:
    """Component-major prediction: ``values`` (4, M), ``jacobian`` (4, 6, M) over ``REDUCED_COLUMNS``
    (empty unless asked for)."""

    values: NDArray[np.float64]
    valid: NDArray[np.bool_]
    range_m: NDArray[np.float64]
    jacobian: NDArray[np.float64] = field(default_factory=lambda: np.zeros((4, 6, 0)))
    has_jacobian: bool = False


def camera_positions(
    map_T_base: ArrayLike, mount: CameraMount | CameraMounts
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Map x, y of the camera for (M, 3) robot poses (vectorized ``CameraMount.camera_pose``)."""
    pose = np.atleast_2d(np.asarray(map_T_base, dtype=float))
    cos_t, sin_t = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    return (
        pose[:, 0] + cos_t * mount.offset_x_m - sin_t * mount.offset_y_m,
        pose[:, 1] + sin_t * mount.offset_x_m + cos_t * mount.offset_y_m,
    )


def _columns(array: ArrayLike, width: int, rows: int) -> NDArray[np.float64]:
    """(width, rows) component-major copy of an (M, width) or (width,) input."""
    a = np.atleast_2d(np.asarray(array, dtype=float))[:, :width]
    return np.ascontiguousarray(np.broadcast_to(a, (rows, width)).T)


def predict_reduced(
    map_T_base: ArrayLike,
    location_m: ArrayLike,
    size_m: ArrayLike,
    mount: CameraMount | CameraMounts,
    *,
    jacobians: bool = True,
) -> ReducedPrediction:
    """Predict slices of M pose/object pairs (rows broadcast), component-major, reduced Jacobian."""
    rows = max(np.atleast_2d(np.asarray(a)).shape[0] for a in (map_T_base, location_m, size_m))
    x, y, theta = _columns(map_T_base, 3, rows)
    lx, ly, lz = _columns(location_m, 3, rows)
    diameter, height = _columns(size_m, 2, rows)

    cos_t, sin_t = np.cos(theta), np.sin(theta)
    ox, oy = mount.offset_x_m, mount.offset_y_m
    dx = lx - (x + cos_t * ox - sin_t * oy)
    dy = ly - (y + sin_t * ox + cos_t * oy)
    dist = np.sqrt(dx * dx + dy * dy)
    radius = 0.5 * diameter
    a = lz + height - mount.height_m  # top face relative to the camera
    b = lz - mount.height_m  # base face relative to the camera

    valid = (dist > np.abs(radius)) & np.isfinite(dist)
    safe_dist = np.where(dist > 0.0, dist, 1.0)
    sine = np.clip(radius / safe_dist, -_MAX_SINE, _MAX_SINE)

    # Which rim is extreme (module docstring): near rim -> -r, far rim -> +r.
    top_side = np.where(a > 0.0, -1.0, 1.0)
    bottom_side = np.where(b > 0.0, 1.0, -1.0)
    rho_top = dist + top_side * radius
    rho_bottom = dist + bottom_side * radius

    values = np.empty((4, rows))
    values[BEARING] = wrap_angle(np.arctan2(dy, dx) - theta - mount.yaw_rad)
    values[WIDTH] = 2.0 * np.arcsin(sine)
    values[ELEVATION_BOTTOM] = np.arctan2(b, rho_bottom)
    values[ELEVATION_TOP] = np.arctan2(a, rho_top)
    if not jacobians:
        return ReducedPrediction(values=values, valid=valid, range_m=dist)

    cosine = np.sqrt(1.0 - sine * sine)
    # d D / d delta and d azimuth / d delta.
    gdx, gdy = dx / safe_dist, dy / safe_dist
    inv_dist2 = 1.0 / (safe_dist * safe_dist)
    # Each component's derivative w.r.t. D (through delta) and w.r.t. r, a, b directly.
    d_width_d_dist = -2.0 * sine / (safe_dist * cosine)
    d_width_d_radius = 2.0 / (safe_dist * cosine)
    norm_top = a * a + rho_top * rho_top
    norm_bottom = b * b + rho_bottom * rho_bottom
    d_top_d_rho, d_top_d_a = -a / norm_top, rho_top / norm_top
    d_bottom_d_rho, d_bottom_d_b = -b / norm_bottom, rho_bottom / norm_bottom

    jac = np.zeros((4, 6, rows))
    jac[BEARING, 0] = -dy * inv_dist2
    jac[BEARING, 1] = dx * inv_dist2
    jac[WIDTH, 0] = d_width_d_dist * gdx
    jac[WIDTH, 1] = d_width_d_dist * gdy
    jac[WIDTH, 4] = 0.5 * d_width_d_radius
    jac[ELEVATION_BOTTOM, 0] = d_bottom_d_rho * gdx
    jac[ELEVATION_BOTTOM, 1] = d_bottom_d_rho * gdy
    jac[ELEVATION_BOTTOM, 3] = d_bottom_d_b
    jac[ELEVATION_BOTTOM, 4] = 0.5 * bottom_side * d_bottom_d_rho
    jac[ELEVATION_TOP, 0] = d_top_d_rho * gdx
    jac[ELEVATION_TOP, 1] = d_top_d_rho * gdy
    jac[ELEVATION_TOP, 3] = d_top_d_a
    jac[ELEVATION_TOP, 4] = 0.5 * top_side * d_top_d_rho
    jac[ELEVATION_TOP, 5] = d_top_d_a
    # theta moves the camera offset (delta changes by (tx, ty)) and turns the bearing.
    tx, ty = sin_t * ox + cos_t * oy, -cos_t * ox + sin_t * oy
    jac[:, 2] = jac[:, 0] * tx + jac[:, 1] * ty
    jac[BEARING, 2] -= 1.0
    return ReducedPrediction(values=values, valid=valid, range_m=dist, jacobian=jac, has_jacobian=True)


def predict_slices(
    map_T_base: ArrayLike,
    location_m: ArrayLike,
    size_m: ArrayLike,
    mount: CameraMount | CameraMounts,
    *,
    jacobians: bool = True,
) -> SlicePrediction:
    """Predict (bearing, angular width, elevation bottom, elevation top) for M pose/object pairs.

    ``map_T_base`` (M, 3), ``location_m`` (M, 3), ``size_m`` (M, 2); rows broadcast.
    """
    red = predict_reduced(map_T_base, location_m, size_m, mount, jacobians=jacobians)
    values = red.values.T
    if not red.has_jacobian:
        return SlicePrediction(values=values, valid=red.valid, range_m=red.range_m)
    jac = red.jacobian.transpose(2, 0, 1)  # (M, 4, 6)
    d_pose = np.concatenate([-jac[:, :, 0:2], jac[:, :, 2:3]], axis=2)
    d_location = np.concatenate([jac[:, :, 0:2], jac[:, :, 3:4]], axis=2)
    return SlicePrediction(
        values=values, valid=red.valid, range_m=red.range_m, d_pose=d_pose, d_location=d_location, d_size=jac[:, :, 4:6]
    )


# What a slice component is (``GraphProblem.measurement_bounds``, (M, 4) in COMPONENTS order):
# a measurement, a bound (the object's value is at least, or at most, the measured one) or
# nothing at all. Edges the view cut off are bounds (objslam_common.records.CUT_*).
MEASURED, LOWER_BOUND, UPPER_BOUND, UNMEASURED = 0, 1, -1, 2


def bounds_of_cuts(cut_edges: ArrayLike, top_at_view_top: ArrayLike) -> NDArray[np.int8]:
    """(M, 4) bounds of slices from the detector's cut edges (``CUT_*`` bits) and the upper
    edges found at the top of the view (objslam_mapper.graph.problem.at_view_top).

    A cut left (counter-clockwise) edge leaves the object reaching further left: its width is
    at least the measured one and its bearing at least the measured one; a cut right edge
    the same with the bearing at most; both: the bearing says nothing. A cut upper edge is a
    lower bound on the object's, a cut lower edge an upper bound.
    """
    cuts = np.asarray(cut_edges, dtype=np.int64).reshape(-1)
    left, right = (cuts & CUT_LEFT) != 0, (cuts & CUT_RIGHT) != 0
    bounds = np.zeros((len(cuts), 4), dtype=np.int8)
    bounds[:, BEARING] = np.select([left & right, left, right], [UNMEASURED, LOWER_BOUND, UPPER_BOUND], MEASURED)
    bounds[:, WIDTH] = np.where(left | right, LOWER_BOUND, MEASURED)
    bounds[:, ELEVATION_TOP] = np.where(
        ((cuts & CUT_TOP) != 0) | np.asarray(top_at_view_top, dtype=bool), LOWER_BOUND, MEASURED
    )
    bounds[:, ELEVATION_BOTTOM] = np.where((cuts & CUT_BOTTOM) != 0, UPPER_BOUND, MEASURED)
    return bounds


def with_side_cuts(bounds: NDArray[np.integer], cut_edges: ArrayLike) -> NDArray[np.int8]:
    """``bounds`` (M, 4) of :func:`bounds_of_cuts` with more edges cut at the sides
    (``CUT_LEFT``/``CUT_RIGHT`` bits, e.g. by a nearer thing): the bearing and width as
    :func:`bounds_of_cuts` makes them from the union of the old and new cuts."""
    bounds = np.array(bounds, dtype=np.int8).reshape(-1, 4)
    cuts = np.asarray(cut_edges, dtype=np.int64).reshape(-1)
    bearing = bounds[:, BEARING]
    left = ((cuts & CUT_LEFT) != 0) | (bearing == LOWER_BOUND) | (bearing == UNMEASURED)
    right = ((cuts & CUT_RIGHT) != 0) | (bearing == UPPER_BOUND) | (bearing == UNMEASURED)
    sides = np.where(left, CUT_LEFT, 0) | np.where(right, CUT_RIGHT, 0)
    recut = bounds_of_cuts(sides, np.zeros(len(cuts), dtype=bool))
    bounds[:, BEARING], bounds[:, WIDTH] = recut[:, BEARING], recut[:, WIDTH]
    return bounds


def censor(error: NDArray[np.float64], bounds: NDArray[np.integer]) -> NDArray[np.float64]:
    """(4, A) 1 where a slice component counts, 0 where it does not.

    A component that is a bound (``bounds`` (A, 4), :func:`bounds_of_cuts`) says only that
    the object's value is beyond it: a one-sided factor, the Gaussian's cost where the model
    lies on the wrong side of the bound and none where it clears it (``error`` (4, A),
    predicted minus measured, in any units of the same sign). Multiplying a component's
    whitened residual and Jacobian row by this gives that factor's residual and its
    (one-sided) Jacobian; the Gaussian normalizer stays, so an object does not gain by
    reaching beyond the view.
    """
    b = np.asarray(bounds).T
    free = (b == UNMEASURED) | ((b == LOWER_BOUND) & (error > 0.0)) | ((b == UPPER_BOUND) & (error < 0.0))
    return np.where(free, 0.0, 1.0)


def whitened_slice_error(
    predicted: NDArray[np.float64],
    measured: NDArray[np.float64],
    inv_sigma: NDArray[np.float64],
    bounds: NDArray[np.integer],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Whitened residuals (4, A) of component-major slices, bearing wrapped, and the weights
    (4, A) that whiten their Jacobians: ``inv_sigma``, zeroed where a component that is a
    bound (``bounds`` (A, 4)) is cleared by the model (:func:`censor`)."""
    error = predicted - measured
    error[BEARING] = wrap_angle(error[BEARING])
    weight = inv_sigma
    if np.any(bounds):
        weight = inv_sigma * censor(error, bounds)
    return error * weight, weight


def slice_error(predicted: ArrayLike, measured: ArrayLike) -> NDArray[np.float64]:
    """predicted - measured (M, 4), with the bearing difference wrapped."""
    error = np.atleast_2d(np.asarray(predicted, dtype=float) - np.asarray(measured, dtype=float)).copy()
    error[:, BEARING] = wrap_angle(error[:, BEARING])
    return error
