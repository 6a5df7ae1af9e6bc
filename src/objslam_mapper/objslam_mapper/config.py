"""Every setting of the mapper, in one place: :class:`MapperConfig` and its sections.

``MapperConfig`` mirrors the ``mapper: ros__parameters:`` section of ``config/mapper.yaml``
key for key and is declared as the mapper node's ROS parameters (nested sections become
dotted names, e.g. ``sampler.screen.floor``). Sections: the camera mount (shared with the
detector, :mod:`objslam_common.mount`), the factor graph's (``odometry``, ``slice_noise``,
``solver``), the association sampler's (``sampler`` with its ``moves``, ``tracklets``,
``clutter``, ``detection`` and ``screen``), the class catalog file, and the node's own
(``ros``, ignored by ``objslam map``). Each field is described once, here; sections and
fields meant for experts say so (``expert=True``), and ``config/mapper.yaml`` and
docs/design.md are generated from these classes (``objslam params``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from objslam_common.config import setting
from objslam_common.mount import CameraMountConfig


@dataclass(frozen=True)
class OdometryCalibrationConfig:
    """Systematic odometry error estimated in the graph: one calibration per map.

    Wheel odometry misreads distance by a scale (mean wheel diameter), turns by a scale
    (effective wheelbase) and adds a turn per metre travelled (left/right wheel diameter
    mismatch), cf. Borenstein's UMBmark. The odometry factor predicts the measured
    increment from the true one with these three (:mod:`objslam_mapper.graph.linearize`).
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
    min_xy_stddev_m: float = setting(
        0.002, "smallest translation stddev of one increment (m)", minimum=1e-9, expert=True
    )
    min_theta_stddev_rad: float = setting(
        0.002, "smallest heading stddev of one increment (rad)", minimum=1e-9, expert=True
    )
    first_pose_stddev_m: float = setting(
        0.001, "prior stddev of the first pose's position (fixes the map frame to odom)", minimum=1e-9, expert=True
    )
    first_pose_stddev_rad: float = setting(
        0.001, "prior stddev of the first pose's heading (rad)", minimum=1e-9, expert=True
    )
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
        expert=True,
    )
    censor_view_top: bool = setting(
        True,
        "a slice of low confidence whose upper edge lies at the top of the camera's view was cut by it: "
        "its upper edge is a lower bound on the object's, which costs only where the model's lies below it",
        expert=True,
    )
    view_top_tolerance_rad: float = setting(
        0.007,
        "an upper edge this close to the highest one seen at its bearing is at the top of the view "
        "(about 3 px at the bundled image's edge)",
        minimum=0.0,
        expert=True,
    )
    low_confidence: float = setting(
        0.5,
        "slices with at most this confidence are likely cut short (the detector halves the confidence of a "
        "blob touching another class or the edge of the view)",
        minimum=0.0,
        maximum=1.0,
        expert=True,
    )
    low_confidence_stddev_scale: float = setting(
        4.0,
        "the noise stddevs of such slices are multiplied by this",
        minimum=1.0,
        expert=True,
    )
    outlier_probability: float = setting(
        0.01,
        "share of the slices assigned to an object that are no measurement of it (a blob merged with a "
        "same-colour neighbour or poster, cut by an occluder): uniform over the measurement space instead "
        "of Gaussian (0: every slice Gaussian)",
        minimum=0.0,
        maximum=0.5,
        expert=True,
    )
    outlier_volume_rad4: float = setting(
        22.746,
        "volume of the slice measurement space an outlier is uniform over (rad^4; default: any bearing, "
        "widths up to 1 rad, ordered edge elevations from -90 deg to the bundled camera's 64 deg: "
        "2 pi * 1 * (pi/2 + 1.12)^2 / 2)",
        minimum=1e-12,
        expert=True,
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
    (``objslam diagnose object-bias bags/small bags/office``: root mean square over the objects
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

    max_iterations: int = setting(50, "most linearizations per solve", minimum=1, expert=True)
    absolute_tolerance: float = setting(
        1e-4,
        "converged when the undamped Gauss-Newton step predicts, or a step achieves, "
        "a drop of the cost (half chi-square) below this",
        minimum=0.0,
        expert=True,
    )
    relative_tolerance: float = setting(0.0, "... plus this fraction of the cost", minimum=0.0, expert=True)
    initial_lambda: float = setting(
        1e-4,
        "Levenberg-Marquardt damping (relative to the diagonal) after a failed Gauss-Newton step",
        minimum=1e-12,
        expert=True,
    )
    max_lambda: float = setting(1e8, "give up when the damping grows beyond this", minimum=1.0, expert=True)
    dense_object_limit: int = setting(
        200,
        "up to this many objects (distractors included) the linear systems are solved by the objects' dense "
        "Schur complement, beyond it by a sparse LU (measured here: the Schur complement is 5x faster at 60 "
        "objects on 900 poses)",
        minimum=0,
        expert=True,
    )
    backend: str = setting(
        "fast",
        "which solver runs each known-association solve: 'fast' (objslam_mapper.graph.solver, numpy) or 'gtsam' "
        "(objslam_mapper.graph.gtsam_backend: the same model as a GTSAM factor graph; same answers, slower)",
    )
    keyframes: KeyframeConfig = setting(KeyframeConfig(), "which images get a graph pose of their own", expert=True)
    error_covariance: ErrorCovarianceConfig = setting(
        ErrorCovarianceConfig(),
        "which covariances a map reports: the estimate's error, or the posterior",
        expert=True,
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


@dataclass(frozen=True)
class TrackletConfig:
    """Gates of the slice chaining (all angles in rad)."""

    bearing_gate_rad: float = setting(
        0.05, "a slice continues a tracklet if its bearing is within this of the predicted interval", minimum=0.0
    )
    elevation_gate_rad: float = setting(
        0.05, "... and each of its edge elevations within this of the predicted interval", minimum=0.0
    )
    width_relative_gate: float = setting(
        0.3, "... and its angular width within this fraction of the predicted width", minimum=0.0
    )
    gate_sigmas: float = setting(
        4.0, "each gate is at least this many standard deviations of the two slices' noise", minimum=0.0
    )
    range_relative_uncertainty: float = setting(
        0.35, "relative uncertainty of the range estimated from apparent size", minimum=0.0, maximum=0.95
    )
    max_frame_gap: int = setting(
        1, "a tracklet may continue this many images after its last slice (1: in the next image)", minimum=1
    )
    max_gap_travel_m: float = setting(
        0.1, "... or in any later image while the robot has travelled at most this (m)", minimum=0.0
    )
    max_gap_turn_rad: float = setting(
        0.05, "... and turned at most this (rad) since the tracklet's last slice", minimum=0.0
    )
    min_length: int = setting(2, "shorter tracklets are dropped (2: drop isolated detections)", minimum=1)
    min_range_m: float = setting(0.2, "range estimates are clipped to at least this (m)", minimum=0.01)
    max_range_m: float = setting(20.0, "range estimates are clipped to at most this (m)", minimum=0.1)


@dataclass(frozen=True)
class ClutterConfig:
    """False-alarm model of the detector (see the module docstring)."""

    enabled: bool = setting(True, "let the sampler explain tracklets as false alarms instead of objects")
    false_alarm_rate: float = setting(
        0.1, "expected false-alarm slices per image and class (Poisson rate)", minimum=1e-12
    )
    max_angular_width_rad: float = setting(1.0, "false-alarm widths are uniform in (0, this] (rad)", minimum=1e-6)
    min_elevation_rad: float = setting(
        -math.pi / 2, "false-alarm edge elevations are uniform above this (rad)", minimum=-math.pi / 2
    )
    max_elevation_rad: float = setting(
        1.12, "... and below this (rad; the bundled camera sees up to asin(0.9) = 1.12)", maximum=math.pi / 2
    )
    distractor_weight: float = setting(
        0.5, "share of a static distractor of unknown shape in the clutter mixture (0: off)", minimum=0.0, maximum=1.0
    )
    distractor_z_base_stddev_m: float = setting(
        1.0, "prior stddev of a distractor's base height around its class's (m)", minimum=1e-3
    )
    distractor_size_stddev_m: float = setting(
        0.5, "prior stddev of a distractor's diameter and height around its class's (m)", minimum=1e-3
    )
    distractor_floor_stddev_m: float = setting(
        0.05,
        "a distractor's base may sink this far under the floor at one stddev (m; one-sided, 0: no floor)",
        minimum=0.0,
    )

    def __post_init__(self) -> None:
        if self.max_elevation_rad <= self.min_elevation_rad:
            raise ValueError("max_elevation_rad must be above min_elevation_rad")

    @property
    def measurement_volume(self) -> float:
        """V: volume of the slice measurement space, rad^4."""
        span = self.max_elevation_rad - self.min_elevation_rad
        return 2.0 * math.pi * self.max_angular_width_rad * 0.5 * span * span

    @property
    def log_likelihood_per_slice(self) -> float:
        """log(rate / V): one false-alarm slice's log density (units: log rad^-4)."""
        return math.log(self.false_alarm_rate) - math.log(self.measurement_volume)

    def log_likelihood(self, slice_count: int) -> float:
        """log L of a tracklet of ``slice_count`` slices explained as clutter."""
        return slice_count * self.log_likelihood_per_slice


@dataclass(frozen=True)
class DetectionConfig:
    """The detector's detection probability and when an object counts as in view."""

    enabled: bool = setting(True, "objects pay for the images where they should be seen and are not")
    probability: float = setting(
        0.7, "probability that an object in view is detected in an image", minimum=1e-6, maximum=1.0 - 1e-6
    )
    min_angular_width_rad: float = setting(
        0.035,
        "a thing in view is detected at the full `probability` from this predicted width up (rad; twice the "
        "detector's narrowest blob: its recall falls below it)",
        minimum=0.0,
    )
    narrowest_width_rad: float = setting(
        0.0175,
        "the detector finds no thing narrower than this (rad; its narrowest blob): from here up to "
        "`min_angular_width_rad` the detection probability rises linearly from 0 to `probability`, and a slice "
        "of a thing predicted narrower pays `narrow_hit_probability` (docs/method.md)",
        minimum=0.0,
    )
    narrow_hit_probability: float = setting(
        0.01,
        "what a slice of a thing predicted too narrow to be detected is worth, as a share of `probability` "
        "(1: slices are never charged for their predicted width)",
        minimum=1e-12,
        maximum=1.0,
    )
    max_range_m: float = setting(
        10.0,
        "... and no farther than this (m): beyond it a detector may lose small or dim objects for reasons "
        "this model does not know, and a real object must not pay for that",
        minimum=0.0,
    )
    view_top_quantile: float = setting(
        0.995,
        "the top of the camera's view is this quantile of all slices' upper edges",
        minimum=0.5,
        maximum=1.0,
    )
    occlusion_cover: float = setting(
        0.5,
        "a thing is hidden when nearer things together cover more than this share of its silhouette "
        "(bearing x elevation, below the top of the view)",
        minimum=0.0,
    )
    occluded_edges: bool = setting(
        True,
        "a slice edge on the silhouette of a nearer thing of another class or a table (in the heuristic start's "
        "map) is a bound on the object's edge, as a view edge is (docs/method.md)",
    )
    occluded_edge_margin_rad: float = setting(
        0.02,
        "a slice edge within this angle of a nearer thing's silhouette counts as on it (rad)",
        minimum=0.0,
        expert=True,
    )
    table_diameter_m: float = setting(
        0.45,
        "objects of a class whose base is above the floor stand on a table this wide (m; docs/design.md), as "
        "tall as their base, which hides what is behind it (0: no tables)",
        minimum=0.0,
    )
    distractor_rate_prior: float = setting(
        0.0,
        "distractors unlike any object of their class are detected at a rate of their own, Beta-distributed "
        "about `probability` with this prior count (a + b): posters and patches are seen from fewer places "
        "than cylinders (0: at `probability`, as objects; docs/method.md)",
        minimum=0.0,
        expert=True,
    )


@dataclass(frozen=True)
class MoveConfig:
    """How the chain proposes new associations (probabilities are normalized over the usable kinds)."""

    merge: float = setting(0.2, "probability of proposing to merge two objects of one class", minimum=0.0)
    split: float = setting(0.2, "probability of proposing to split one object in two", minimum=0.0)
    reassign: float = setting(0.3, "probability of moving one tracklet to another or a new object", minimum=0.0)
    to_clutter: float = setting(0.15, "probability of moving one tracklet to the clutter set", minimum=0.0)
    from_clutter: float = setting(0.15, "probability of moving a clutter tracklet into an object", minimum=0.0)
    dissolve: float = setting(
        0.05, "probability of moving every tracklet of an object (of two or more) to the clutter set", minimum=0.0
    )
    gather: float = setting(
        0.05, "probability of making a new object of two or more clutter tracklets of one class", minimum=0.0
    )
    dissolve_pair: float = setting(
        0.05,
        "probability of moving every tracklet of two objects of one class to the clutter set (one thing held as "
        "two objects)",
        minimum=0.0,
    )
    gather_pair: float = setting(
        0.05, "probability of making two new objects of clutter tracklets of one class", minimum=0.0
    )
    gather_into: float = setting(
        0.05,
        "probability of moving two or more clutter tracklets of one class into an existing object at once",
        minimum=0.0,
    )
    shed: float = setting(
        0.05,
        "probability of moving two or more tracklets of an object (of three or more) to the clutter set at once",
        minimum=0.0,
    )
    informed: float = setting(
        0.2,
        "probability of sending one tracklet (any) where the screen judges it fits: another object of its class, "
        "a new object or the clutter set",
        minimum=0.0,
    )
    informed_group: float = setting(
        0.1,
        "probability of gathering a whole clutter thing into a new object, or dissolving an object into one clutter "
        "thing, chosen where the screen judges it fits",
        minimum=0.0,
    )
    balanced: float = setting(
        0.2,
        "probability of sending one short tracklet where the screen judges it fits, the tracklet chosen by the "
        "screen too (among every short tracklet's nearest objects, a new object and the clutter set)",
        minimum=0.0,
    )
    balanced_max_weight: float = setting(
        5.0,
        "the balanced move takes tracklets of at most this many slices (each costs a screen per destination; a "
        "longer tracklet's place is rarely in doubt)",
        minimum=0.0,
    )
    balanced_objects: int = setting(
        3,
        "the balanced move weighs, for each tracklet, this many nearest objects of its class (and a new object and "
        "the clutter set)",
        minimum=1,
    )
    distance_scale_m: float = setting(
        1.0, "merges and reassignments prefer objects within about this distance (m)", minimum=1e-3
    )
    weight_floor: float = setting(
        0.01, "proposal weight of an object however far away (keeps every move possible)", minimum=1e-9
    )
    new_object_weight: float = setting(
        0.2, "proposal weight of 'a new object' (an existing object at distance 0 weighs 1)", minimum=1e-9
    )
    split_randomness: float = setting(
        0.2,
        "share of a split decided by a coin flip instead of by distance to the two seeds",
        minimum=1e-3,
        maximum=1.0,
    )

    def __post_init__(self) -> None:
        if self.merge + self.split + self.reassign <= 0.0:
            raise ValueError("merge, split and reassign probabilities cannot all be zero")
        if (self.merge > 0.0) != (self.split > 0.0):
            raise ValueError("merge and split are each other's reverse: both or neither must be > 0")
        if (self.to_clutter > 0.0) != (self.from_clutter > 0.0):
            raise ValueError("to_clutter and from_clutter are each other's reverse: both or neither must be > 0")
        if (self.dissolve > 0.0) != (self.gather > 0.0):
            raise ValueError("dissolve and gather are each other's reverse: both or neither must be > 0")
        if (self.dissolve_pair > 0.0) != (self.gather_pair > 0.0):
            raise ValueError("dissolve_pair and gather_pair are each other's reverse: both or neither must be > 0")
        if (self.gather_into > 0.0) != (self.shed > 0.0):
            raise ValueError("gather_into and shed are each other's reverse: both or neither must be > 0")


@dataclass(frozen=True)
class ScreenConfig:
    """Delayed acceptance: a proposal is first screened on the objects it moves (poses fixed at
    the current state's MAP), and only one that passes costs a graph solve; the second stage
    corrects for the screen, so the chain's target stays exact (docs/method.md)."""

    enabled: bool = setting(True, "screen proposals before a graph solve (false: every proposal is solved)")
    margin_nats: float = setting(
        5.0, "the screen lets through proposals it judges worse by up to this much (nats)", minimum=0.0
    )
    relative_margin: float = setting(
        0.1, "... or by up to this fraction of its log ratio, whichever is larger", minimum=0.0
    )
    floor: float = setting(
        0.01,
        "a proposal the screen condemns still gets a graph solve with this probability",
        minimum=1e-6,
        maximum=1.0,
    )
    join_floor: float = setting(
        0.1,
        "... this one when it joins tracklets of two objects (or of clutter and an object) or parts them: "
        "closing (or opening) a loop needs the poses to move, which the screen cannot see",
        minimum=1e-6,
        maximum=1.0,
    )
    far_join_m: float = setting(
        3.0,
        "a move that joins or parts tracklets this far apart (m; rough positions or lines of sight) always "
        "gets a graph solve: a wrong far join bends the poses the screen is judged at (0: never)",
        minimum=0.0,
    )


CHAIN_STARTS = ("heuristic", "singletons", "greedy", "clutter", "random")
POOLINGS = ("target", "counts")


@dataclass(frozen=True)
class SamplerConfig:
    """The association sampler and map building (the mapper's ``sampler.*`` parameters)."""

    chains: int = setting(
        4,
        "Metropolis-Hastings chains, each from its own start (see starts), their kept samples pooled for the "
        "map; with 2 or more the map says whether they agree (converged)",
        minimum=1,
    )
    samples: int = setting(6000, "MH steps of each chain, burn-in included (paper: 6000)", minimum=1)
    burn_in: int = setting(2500, "first steps of each chain left out of the map (paper: 2500)", minimum=0)
    seed: int = setting(
        1, "random seed: the chains' seeds are derived from it (same seed, same inputs: same map)", minimum=0
    )
    starts: tuple[str, ...] = setting(
        ("heuristic", "singletons", "greedy", "clutter"),
        "the start of each chain in turn, dispersed on purpose: heuristic (near neighbours joined, the likely "
        "clutter cleared), singletons (every tracklet its own object), greedy (nearest neighbour with a "
        "Mahalanobis gate), clutter (every tracklet clutter), random (a random association); chains beyond "
        "the list start random",
        expert=True,
    )
    pooling: str = setting(
        "target",
        "how the chains' kept states make the map: target (each distinct kept state weighted by its target "
        "value, so a chain stuck far below the others adds nothing) or counts (by how often the chains kept "
        "it: paper Algorithm 1 over the pooled samples)",
        expert=True,
    )
    rhat_max: float = setting(
        1.01,
        "the chains agree (converged) when every R-hat (log target, objects, each reported identity) is at "
        "most this and every reported identity is on the same side of 1/2 in every chain",
        minimum=1.0,
        expert=True,
    )
    moves: MoveConfig = setting(MoveConfig(), "proposal moves", expert=True)
    tracklets: TrackletConfig = setting(TrackletConfig(), "chaining slices into tracklets", expert=True)
    clutter: ClutterConfig = setting(ClutterConfig(), "false-alarm model", expert=True)
    spurious_location_stddev_m: float = setting(
        0.30, "an object whose horizontal location stddev (largest axis) exceeds this is spurious (m)", minimum=0.0
    )
    existence_threshold: float = setting(
        0.5, "identities with P(ID|Z) above this make the map", minimum=0.0, maximum=1.0
    )
    report_min_fraction: float = setting(
        0.05, "other identities held by at least this fraction of samples are reported as rejected", minimum=0.0
    )
    identity_overlap: float = setting(
        0.8,
        "two sample objects are one identity when each holds at least this share of the other's measurements "
        "(1: the paper's exact identity)",
        minimum=0.501,
        maximum=1.0,
        expert=True,
    )
    initial_merge_distance_m: float = setting(
        0.6,
        "start state: a tracklet joins the nearest same-class object within this distance (m)",
        minimum=0.0,
        expert=True,
    )
    exclusion: bool = setting(
        True,
        "objects are solid: an association pays the posterior probability that two of its objects overlap",
        expert=True,
    )
    exclusion_floor_nats: float = setting(
        -60.0,
        "... each pair at most this much: with exp(floor) the prior does not hold (one object on another)",
        maximum=0.0,
        expert=True,
    )
    detection: DetectionConfig = setting(
        DetectionConfig(), "detection probability and visibility of objects", expert=True
    )
    initial_clutter: bool = setting(
        True,
        "start state: a tracklet the target prefers as clutter over a lone object starts in clutter, then start "
        "objects the target prefers as clutter go there, each clutter tracklet is tried once in its nearest object, "
        "and the objects are tried as clutter again (false: the plain nearest-neighbour start)",
        expert=True,
    )
    proposal_max_iterations: int = setting(
        15, "most solver linearizations per proposed association", minimum=1, expert=True
    )
    settle_within_nats: float = setting(
        50.0,
        "a proposal whose capped solve stopped unconverged, valued less than this many nats "
        "below the chain's state or above it, is solved on (the solver's own iteration budget) "
        "before it is judged: an unconverged value can lie far above the optimum's; 0: never",
        minimum=0.0,
        expert=True,
    )
    solution_cache_size: int = setting(
        256, "graph solutions kept for warm starts and map building", minimum=1, expert=True
    )
    sightings_cache_mb: int = setting(
        256,
        "megabytes of per-state sightings (how each state's things appear from every pose) a chain keeps; "
        "about 5 MB a state on a 900-image run. Evicted ones are computed again, to the same numbers",
        minimum=1,
        expert=True,
    )
    screen: ScreenConfig = setting(
        ScreenConfig(), "delayed acceptance: a cheap first look at each proposal", expert=True
    )

    def __post_init__(self) -> None:
        if self.burn_in >= self.samples:
            raise ValueError(f"burn_in ({self.burn_in}) must be smaller than samples ({self.samples})")
        unknown = [s for s in self.starts if s not in CHAIN_STARTS]
        if unknown:
            raise ValueError(f"unknown chain start {unknown[0]!r} (one of {', '.join(CHAIN_STARTS)})")
        if self.pooling not in POOLINGS:
            raise ValueError(f"pooling must be one of {', '.join(POOLINGS)}, got {self.pooling!r}")


@dataclass(frozen=True)
class RosConfig:
    """The mapper node's topics, buffers and outputs (not used by ``objslam map``)."""

    odom_topic: str = setting("/odom", "wheel odometry (nav_msgs/Odometry, odom -> base_link)")
    slices_topic: str = setting("/objslam/slices", "detector output (objslam_msgs/SliceArray)")
    max_buffered_odometry: int = setting(200_000, "odometry messages kept; the oldest go first", minimum=1)
    max_buffered_images: int = setting(50_000, "slice arrays kept; the oldest go first", minimum=1)
    subscription_depth: int = setting(1000, "subscription queue depth (reliable): room for bursts", minimum=1)
    output_dir: str = setting("", "if set, write map.yaml here after each build")


PARALLEL_BACKENDS = ("ray", "inprocess")


@dataclass(frozen=True)
class ParallelConfig:
    """Where the chains run: Ray tasks (a local Ray started on demand, or an existing cluster) or
    one after another in this process. One chain always runs in this process."""

    backend: str = setting("ray", "ray (chains as Ray tasks, in parallel) or inprocess (one after another)")
    ray_address: str = setting(
        "",
        "an existing Ray cluster to run the chains on (e.g. 10.0.0.5:6379, or auto); empty: the RAY_ADDRESS "
        "environment variable if set, else a local Ray started on demand",
    )
    workers: int = setting(0, "CPUs of a local Ray (0: every core of this machine)", minimum=0)

    def __post_init__(self) -> None:
        if self.backend not in PARALLEL_BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(PARALLEL_BACKENDS)}, got {self.backend!r}")
        if self.workers < 0:
            raise ValueError(f"workers must be >= 0 (0: every core), got {self.workers}")


@dataclass(frozen=True)
class MapperConfig:
    """The mapper's whole configuration: ``objslam map`` and the mapper node read the same."""

    catalog_file: str = setting("", "class catalog file; empty = the bundled config/catalog.yaml")
    camera_mount: CameraMountConfig = setting(CameraMountConfig(), "camera mount on the robot")
    odometry: OdometryNoiseConfig = setting(OdometryNoiseConfig(), "odometry factor noise")
    slice_noise: SliceNoiseConfig = setting(SliceNoiseConfig(), "slice measurement noise")
    solver: SolverConfig = setting(SolverConfig(), "known-association solver")
    sampler: SamplerConfig = setting(SamplerConfig(), "association sampler and map building")
    parallel: ParallelConfig = setting(ParallelConfig(), "where the chains run")
    ros: RosConfig = setting(RosConfig(), "mapper node topics, buffers and outputs")

    @property
    def graph(self) -> GraphConfig:
        return GraphConfig(
            camera_mount=self.camera_mount, odometry=self.odometry, slice_noise=self.slice_noise, solver=self.solver
        )
