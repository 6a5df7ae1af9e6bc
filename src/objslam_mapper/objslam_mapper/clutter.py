r"""The false-alarm (clutter) model: the likelihood of a tracklet that is no object.

Beyond the paper, an association may put a tracklet in the clutter set: its slices are
then explained by something that is not an object of the map. For the comparison with an
object to be meaningful, both must be densities over the same measurements in the same
units. The object side is the factor graph's Laplace evidence, which includes every
Gaussian normalizer (:mod:`objslam_mapper.solver`): a density over each slice's 4-vector
``(bearing, angular width, elevation bottom, elevation top)`` in rad^-4. The clutter side
is a mixture of two densities over the same 4-vectors:

independent false alarms (weight ``1 - distractor_weight``)
    false alarms of a class are a Poisson process with ``false_alarm_rate`` expected
    slices per image, each uniform over the measurement space

        bearing in [-pi, pi),  width in (0, w_max],  e_min <= bottom <= top <= e_max,

    of volume ``V = 2 pi * w_max * (e_max - e_min)^2 / 2`` rad^4. Up to factors that do
    not depend on the association (``exp(-rate)`` per image and class), a tracklet of
    ``n`` slices has ``log L = n (log rate - log V)``. With the default noise a slice that
    fits an object is worth about ``+15`` nats to it (its Gaussian normalizer) against
    ``-5.4`` here, so this only takes slices that fit no object at all.

a static distractor (weight ``distractor_weight``)
    a poster or a sign is seen consistently from image to image, which independent
    false alarms are not; what gives it away is that it is not shaped or placed like an
    object of its class (it floats, or is flat). It is modelled as a cylinder *of unknown
    geometry*: the same slice model, but with broad priors on ``z_base`` and size
    (``distractor_z_base_stddev_m``, ``distractor_size_stddev_m``) instead of the class
    priors, and ``log L`` its Laplace evidence alone with the odometry chain (whose own
    evidence is 0). A real object's tracklet prefers its class by the Occam factor of the
    tighter priors (several nats); a poster that would need ``z_base`` tens of prior
    standard deviations off the floor prefers the distractor by hundreds.

    The distractor's evidence is computed with the trajectory to itself: the information
    its slices carry about the robot's poses is not shared with the objects' graph. That
    approximation leaves the object-or-distractor comparison of a tracklet as it is when
    the tracklet moves the trajectory little, which is the case for the short or
    misfitting tracklets it is about.

    What this leaves out is measurable. The map's objects pin the trajectory down, and a
    tracklet's slices fit that trajectory better than the odometry alone: on the bundled
    ``clutter`` bag its evidence rises by 50 to 90 nats for 40 to 80 slices. The object
    side of the target gets that (it is in the joint graph), this side does not. A floor
    patch's tracklet alone still prefers the distractor by 45 to 165 nats (a flat patch
    fits a class only tens of prior stddevs off its height), but merged in one object
    with the patch's other tracklets it is within about 50 nats, one of five such patches
    even ahead by 27. The start state keeps the chain away from those objects
    (:mod:`objslam_mapper.inference`, ``initial_clutter``); evaluating the distractor in
    the map's trajectory (a distractor as a group of the association, solved in the joint
    graph with these broad priors) would remove the bias from the target itself. Holding
    the poses fixed at a reference trajectory instead overshoots: it gains 40 to 60 nats
    more than the joint graph does on long tracklets and would turn real objects into
    clutter.

Missed detections are modelled on neither side (an object is detected with probability
one wherever it was seen).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from objslam_mapper.backends import solve_with_backend
from objslam_mapper.config import setting
from objslam_mapper.problem import GraphProblem, gaussian_log_normalizer


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


def distractor_problem(problem: GraphProblem, config: ClutterConfig) -> GraphProblem:
    """``problem`` with every class's z_base and size priors widened to the distractor's."""
    stddev = np.array(problem.prior_stddev)
    stddev[:, 2] = config.distractor_z_base_stddev_m
    stddev[:, 3:] = config.distractor_size_stddev_m
    stddev.flags.writeable = False
    normalizer = gaussian_log_normalizer(stddev)
    normalizer.flags.writeable = False
    return dataclasses.replace(problem, prior_stddev=stddev, prior_log_normalizer=normalizer)


class ClutterModel:
    """log L_clutter of tracklets of one problem (see the module docstring)."""

    def __init__(self, problem: GraphProblem, config: ClutterConfig):
        self.config = config
        self._distractors = distractor_problem(problem, config) if config.distractor_weight > 0.0 else None

    def distractor_log_evidence(self, measurement_indices: Sequence[int]) -> float:
        if self._distractors is None:
            return -math.inf
        return solve_with_backend(self._distractors, [np.asarray(measurement_indices, dtype=np.int64)]).log_evidence

    def tracklet_log_likelihood(self, measurement_indices: Sequence[int]) -> float:
        w = self.config.distractor_weight
        independent = self.config.log_likelihood(len(measurement_indices))
        if w == 0.0:
            return independent
        distractor = self.distractor_log_evidence(measurement_indices)
        if w == 1.0:
            return distractor
        return float(np.logaddexp(math.log1p(-w) + independent, math.log(w) + distractor))
