"""Settings of the factor-graph model and its solver (the mapper's ``odometry.*``,
``slice_noise.*``, ``solver.*`` and ``camera_mount.*`` parameters).

Defaults live in ``config/mapper.yaml`` under ``mapper: ros__parameters:``; the mapper's
full config dataclass holds these sections beside its own (e.g. ``sampler.*``).
:func:`load_graph_config` reads just these sections from such a file.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

from objslam_common.config import from_mapping, read_ros_parameters, setting
from objslam_common.mount import CameraMountConfig


@dataclass(frozen=True)
class OdometryCalibrationConfig:
    """Systematic odometry error estimated in the graph: one calibration per map.

    Wheel odometry misreads distance by a scale (mean wheel diameter), turns by a scale
    (effective wheelbase) and adds a turn per metre travelled (left/right wheel diameter
    mismatch), cf. Borenstein's UMBmark. The odometry factor predicts the measured
    increment from the true one with these three (:mod:`objslam_mapper.graph.normal_equations`).
    The zero-mean Gaussian prior only has to keep them in a plausible range, not to know
    the robot: stock differential-drive robots are off by about 1-3 % in distance and
    turn before calibration (tyre pressure, wear, the contact point of wide wheels), so
    5 % is a generous 1-sigma; a 0.02 rad/m bias is a left/right diameter mismatch of
    about 1 % on a 0.4 m wheelbase, several times what UMBmark finds on real robots.
    """

    enabled: bool = setting(
        True,
        "estimate the odometry's distance scale, turn scale and turn bias per metre with the map "
        "(false: odometry increments are taken as unbiased, the random walk alone)",
    )
    distance_scale_stddev: float = setting(
        0.05, "prior stddev of the distance scale error (measured distance = (1 + scale) true)", minimum=1e-9
    )
    turn_scale_stddev: float = setting(
        0.05, "prior stddev of the turn scale error (measured turn = (1 + scale) true turn + ...)", minimum=1e-9
    )
    turn_bias_stddev_rad_per_m: float = setting(
        0.02, "prior stddev of the spurious turn per metre travelled (rad/m)", minimum=1e-9
    )

    def prior_stddev(self) -> tuple[float, float, float]:
        return (self.distance_scale_stddev, self.turn_scale_stddev, self.turn_bias_stddev_rad_per_m)


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Noise of the odometry factor between consecutive image poses.

    The random part of the odometry error is a random walk: the variance of an increment grows linearly with
    the path length and with the absolute angle turned over it, so it does not depend on
    how often images were taken. Values are standard deviations after 1 m of travel or
    1 rad of turn; the minimum keeps standing still well-conditioned. The systematic part
    (scales and bias) is the ``calibration`` variable of the graph.
    """

    xy_stddev_per_sqrt_m: float = setting(
        0.05, "translation stddev (m) accumulated over 1 m of travel (variance grows with distance)", minimum=0.0
    )
    xy_stddev_per_sqrt_rad: float = setting(0.02, "translation stddev (m) accumulated over 1 rad of turn", minimum=0.0)
    theta_stddev_per_sqrt_m: float = setting(0.03, "heading stddev (rad) accumulated over 1 m of travel", minimum=0.0)
    theta_stddev_per_sqrt_rad: float = setting(0.05, "heading stddev (rad) accumulated over 1 rad of turn", minimum=0.0)
    min_xy_stddev_m: float = setting(0.002, "smallest translation stddev of one increment (m)", minimum=1e-9)
    min_theta_stddev_rad: float = setting(0.002, "smallest heading stddev of one increment (rad)", minimum=1e-9)
    first_pose_stddev_m: float = setting(
        0.001, "prior stddev of the first pose's position (fixes the map frame to odom)", minimum=1e-9
    )
    first_pose_stddev_rad: float = setting(0.001, "prior stddev of the first pose's heading (rad)", minimum=1e-9)
    calibration: OdometryCalibrationConfig = setting(
        OdometryCalibrationConfig(), "systematic odometry error (scale and bias) estimated with the map"
    )


@dataclass(frozen=True)
class SliceNoiseConfig:
    """Gaussian noise of a slice measurement (rad, camera frame).

    Defaults suit a colour-blob detector on the bundled 640x640 image, where one pixel
    near the horizon spans about 0.3 deg: the bearing averages two blob edges, the width
    and the elevations each depend on one or two edges and on the blob's shading.

    A slice is Gaussian around the prediction with probability ``1 - outlier_probability``
    and otherwise uniform over the measurement space (:mod:`objslam_mapper.model.outliers`).
    """

    bearing_stddev_rad: float = setting(0.006, "bearing (slice centre azimuth) stddev (rad)", minimum=1e-9)
    angular_width_stddev_rad: float = setting(0.012, "angular width stddev (rad)", minimum=1e-9)
    elevation_bottom_stddev_rad: float = setting(0.010, "lower edge elevation stddev (rad)", minimum=1e-9)
    elevation_top_stddev_rad: float = setting(0.010, "upper edge elevation stddev (rad)", minimum=1e-9)
    raised_elevation_bottom_stddev_rad: float = setting(
        0.15,
        "lower edge elevation stddev (rad) for classes standing above the camera on a support, "
        "whose top hides the object's lowest part (the measured edge is then the support's rim)",
        minimum=1e-9,
    )
    censor_view_top: bool = setting(
        True,
        "a slice of low confidence whose upper edge lies at the top of the camera's view was cut by it: "
        "its upper edge is a lower bound on the object's, which costs only where the model's lies below it",
    )
    view_top_tolerance_rad: float = setting(
        0.007,
        "an upper edge this close to the highest one seen at its bearing is at the top of the view "
        "(about 3 px at the bundled image's edge)",
        minimum=0.0,
    )
    low_confidence: float = setting(
        0.5,
        "slices with at most this confidence are likely cut short (the detector halves the confidence of a "
        "blob touching another class or the edge of the view)",
        minimum=0.0,
        maximum=1.0,
    )
    low_confidence_stddev_scale: float = setting(
        4.0, "the noise stddevs of such slices are multiplied by this", minimum=1.0
    )
    outlier_probability: float = setting(
        0.01,
        "share of the slices assigned to an object that are no measurement of it (a blob merged with a "
        "same-colour neighbour or poster, cut by an occluder): uniform over the measurement space instead "
        "of Gaussian (0: every slice Gaussian)",
        minimum=0.0,
        maximum=0.5,
    )
    outlier_volume_rad4: float = setting(
        22.746,
        "volume of the slice measurement space an outlier is uniform over (rad^4; default: any bearing, "
        "widths up to 1 rad, ordered edge elevations from -90 deg to the bundled camera's 64 deg: "
        "2 pi * 1 * (pi/2 + 1.12)^2 / 2)",
        minimum=1e-12,
    )


SOLVER_BACKENDS = ("fast", "gtsam")


@dataclass(frozen=True)
class KeyframeConfig:
    """Which images get a robot pose of their own in the factor graph (objslam_mapper.graph.keyframes).

    An image becomes a keyframe once the odometry has travelled ``min_travel_m`` or turned
    ``min_turn_rad`` since the last keyframe; the images between are tied to the keyframe
    before them by their odometry (its noise added to their slices'). The graph then
    grows with the path, not with the frame rate. Only when that removes at least
    ``min_reduction`` of the poses: at the bundled bags' rate (about 8 cm between images)
    it would only join the few images taken while the robot stands, and there one pose per
    image is kept, as the paper has it.
    """

    enabled: bool = setting(True, "tie images taken close together to one graph pose (false: one pose per image)")
    min_travel_m: float = setting(
        0.05, "an image is a keyframe once the robot has travelled this far since the last keyframe (m)", minimum=0.0
    )
    min_turn_rad: float = setting(0.05, "... or turned this much (rad)", minimum=0.0)
    min_reduction: float = setting(
        0.25,
        "keyframes are used only when they remove at least this share of the poses (else one pose per image: "
        "a small gain is not worth the approximation)",
        minimum=0.0,
        maximum=1.0,
    )


@dataclass(frozen=True)
class ErrorCovarianceConfig:
    """Which covariances a map reports (objslam_mapper.graph.error_covariance).

    On: the covariance of the estimate's error, with each noise group's level measured
    from the residuals and a bias common to all slices of one object. Off: the posterior
    under the configured noise, which is generous on purpose (the association needs it)
    and so overstates the error several times. Either way the MAP, the evidence and the
    existence test are the model's. A bias share is the bias's stddev in units of each
    slice's configured stddev; the defaults are the detector's on the bundled bags
    (``scripts/object_bias.py bags/small bags/office``: root mean square over the objects
    of the mean of each object's whitened slice errors at the ground truth, rounded).
    The class priors count with the spread of real instances about their means: as stated
    for sizes and raised objects' base heights, ``floor_z_base_spread_m`` for floor objects,
    whose catalog prior (1 cm) is looser than the floor on purpose (a tighter one turns the
    detector's lower-edge bias into range error).
    """

    enabled: bool = setting(
        True,
        "report the covariance of the estimate's error (noise levels from the residuals, a bias per object) "
        "instead of the posterior under the configured noise",
    )
    bearing_bias_share: float = setting(
        0.04,
        "stddev of a bearing error common to all slices of an object, in units of the slices' configured stddev",
        minimum=0.0,
    )
    angular_width_bias_share: float = setting(0.11, "... of the angular width", minimum=0.0)
    elevation_bottom_bias_share: float = setting(0.11, "... of the lower edge elevation", minimum=0.0)
    elevation_top_bias_share: float = setting(0.065, "... of the upper edge elevation", minimum=0.0)
    floor_z_base_spread_m: float = setting(
        0.0,
        "stddev of real floor objects' base heights about the floor (m; 0: they stand on it). The error "
        "covariance counts this, not the catalog's looser floor prior, which is slack for the MAP",
        minimum=0.0,
    )

    def bias_shares(self) -> tuple[float, float, float, float]:
        """Per slice component, in the order of objslam_mapper.model.slice_model.COMPONENTS."""
        return (
            self.bearing_bias_share,
            self.angular_width_bias_share,
            self.elevation_bottom_bias_share,
            self.elevation_top_bias_share,
        )


@dataclass(frozen=True)
class SolverConfig:
    """Gauss-Newton / Levenberg-Marquardt loop of the known-association solve."""

    max_iterations: int = setting(50, "most linearizations per solve", minimum=1)
    absolute_tolerance: float = setting(
        1e-4, "converged when the cost (half chi-square) drops by less than this", minimum=0.0
    )
    relative_tolerance: float = setting(0.0, "... plus this fraction of the cost", minimum=0.0)
    initial_lambda: float = setting(
        1e-4, "Levenberg-Marquardt damping (relative to the diagonal) after a failed Gauss-Newton step", minimum=1e-12
    )
    max_lambda: float = setting(1e8, "give up when the damping grows beyond this", minimum=1.0)
    dense_object_limit: int = setting(
        200,
        "up to this many objects (distractors included) the linear systems are solved by the objects' dense "
        "Schur complement, beyond it by a sparse LU (measured here: the Schur complement is 5x faster at 60 "
        "objects on 900 poses)",
        minimum=0,
    )
    backend: str = setting(
        "fast",
        "which solver runs each known-association solve: 'fast' (objslam_mapper.graph.solver, numpy) or 'gtsam' "
        "(objslam_mapper.graph.gtsam_backend: the same model as a GTSAM factor graph; same answers, slower)",
    )
    keyframes: KeyframeConfig = setting(KeyframeConfig(), "which images get a graph pose of their own")
    error_covariance: ErrorCovarianceConfig = setting(
        ErrorCovarianceConfig(), "which covariances a map reports: the estimate's error, or the posterior"
    )

    def __post_init__(self) -> None:
        if self.backend not in SOLVER_BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(SOLVER_BACKENDS)}, got {self.backend!r}")


@dataclass(frozen=True)
class GraphConfig:
    """Everything the factor graph needs besides the catalog."""

    camera_mount: CameraMountConfig = setting(CameraMountConfig(), "camera mount on the robot")
    odometry: OdometryNoiseConfig = setting(OdometryNoiseConfig(), "odometry factor noise")
    slice_noise: SliceNoiseConfig = setting(SliceNoiseConfig(), "slice measurement noise")
    solver: SolverConfig = setting(SolverConfig(), "known-association solver")


GRAPH_SECTIONS = tuple(f.name for f in dataclasses.fields(GraphConfig))


def load_graph_config(path: str | os.PathLike[str] | None, node_name: str = "mapper") -> GraphConfig:
    """The graph sections of a node's parameter file; its other sections are left to their owners."""
    if path is None:
        return GraphConfig()
    params = read_ros_parameters(path, node_name)
    return from_mapping(GraphConfig, {k: v for k, v in params.items() if k in GRAPH_SECTIONS})
