r"""The false-alarm (clutter) model: the likelihood of a tracklet that is no object.

Beyond the paper, an association may put a tracklet in the clutter set: its slices are
then explained by something that is not an object of the map. For the comparison with an
object to be meaningful, both must be densities over the same measurements in the same
units. The object side is the factor graph's Laplace evidence, which includes every
Gaussian normalizer (:mod:`objslam_mapper.graph.solver`): a density over each slice's 4-vector
``(bearing, angular width, elevation bottom, elevation top)`` in rad^-4. The clutter side
has two components over the same 4-vectors:

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
    priors. A distractor is a thing in the world like an object, so it is part of the
    factor graph: each distractor of the clutter set (one tracklet, or several that are one
    thing) is one more variable of the association's graph, with those priors
    (:meth:`.target.AssociationTarget.graph_groups`), and its
    ``log L`` is what it adds to the graph's Laplace evidence, plus ``log w``. It thus
    gets the trajectory the whole map pins down, as an object does: a tracklet's slices
    fit the map's trajectory better than the odometry alone (on the ``clutter`` scenario
    by 50 to 90 nats for 40 to 80 slices), and scoring a distractor with the odometry
    alone while the objects get the map's would have handed that margin to "object"
    (a flat patch on the floor, several tracklets merged, then beat clutter). A real
    object's tracklet still prefers its class by the Occam factor of the tighter priors
    (several nats); a poster that would need ``z_base`` tens of prior standard deviations
    off the floor prefers the distractor by hundreds. Broad as they are, those priors
    would let a map of distractors alone grow about the camera with every base under the
    floor; a one-sided floor factor (``distractor_floor_stddev_m``,
    :mod:`objslam_mapper.model.floor`) keeps a distractor's base above it.

The mixture of the two components is approximated by its larger term, chosen once per
tracklet (:meth:`ClutterModel.component`): the component whose ``log L`` is larger with
the odometry alone. The choice is a fixed function of the tracklet, so the target stays a
fixed function of the association; the max of a two-term mixture is within ``log 2`` of
it. A distractor's ``log L`` there includes the missed detections it pays in the target
(:mod:`objslam_mapper.inference.detection`), the images where that static thing, alone,
should have been seen and was not: a static thing seen in 2 of the 100 images that face it
is no static thing. Left out, a 2-slice tracklet chose "distractor" (its slices fit one by
40 nats) and then paid 100 to 300 nats of misses in every state that had it in clutter, so
the chain put it anywhere else: its own object (a ghost), or the outlier slices of a real
object of its class metres away, whose capped cost is a few nats; on a ``twins`` bag three
of four chains sat 126 nats below the fourth on such a choice and never met it. A thing is
often seen in several tracklets (a patch passed twice, a poster cut by a nearer object), so
an image with a slice of its class over the thing's predicted bearing interval is no miss,
whichever tracklet the slice is in: without that, the fragments of patches each paid the
images the others saw, became independent false alarms at ~20 nats per slice, and gathered
they were cheaper as objects (on ``clutter`` seed 1, five patches mapped where three were).
Alone, with nothing in front of it, a thing's misses are still overcounted where other
things hide it; that errs towards independent false alarms, which pay no misses, only for
tracklets short enough that a few hundred nats of misses outweigh the ~20 nats per slice a
static thing is worth over false alarms. A long tracklet of a real thing stays a distractor.
In practice a tracklet that fits a static thing seen where it should be is a distractor, and
one that does not (slices of nothing consistent, or of something seen far too rarely)
independent false alarms.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_mapper.config import ClutterConfig
from objslam_mapper.graph.backends import solve_with_backend
from objslam_mapper.graph.problem import GraphProblem, with_extra_priors
from objslam_mapper.graph.solver import GraphSolution
from objslam_mapper.model.floor import NO_FLOOR

INDEPENDENT = "independent"
DISTRACTOR = "distractor"

# A distractor whose shape is this many class-prior standard deviations off its class's is
# no object of the class seen in fragments (it shares its hits with the others of its kind).
UNLIKE_CLASS_SIGMAS = 3.0


def distractor_priors(problem: GraphProblem, config: ClutterConfig) -> tuple[NDArray, NDArray]:
    """Prior rows (L, 5) of a distractor of each class: the class's, with z_base and size widened."""
    classes = len(problem.labels)
    mean = np.array(problem.prior_mean[:classes])
    stddev = np.array(problem.prior_stddev[:classes])
    stddev[:, 2] = config.distractor_z_base_stddev_m
    stddev[:, 3:] = config.distractor_size_stddev_m
    return mean, stddev


class DistractorFit(NamedTuple):
    """Slices fitted as one distractor with the odometry alone."""

    solution: GraphSolution
    prior_row: int
    # Unlike any object of its class: base height, diameter or height more than
    # UNLIKE_CLASS_SIGMAS class-prior standard deviations from the class's (it shares its hits).
    unlike_class: bool


MissPrice = Callable[[DistractorFit], float]  # the detection term a distractor pays alone


@dataclass(frozen=True)
class Component:
    """The clutter component that explains one tracklet, and its terms of the target."""

    kind: str  # INDEPENDENT or DISTRACTOR
    # Added to log P(J|Z) when the tracklet is clutter: log(1 - w) + n log(rate / V) for
    # independent false alarms, log w for a distractor (whose slices are in the graph).
    log_weight: float
    alone_log_likelihood: float  # log L with the odometry alone, a distractor's misses included (the choice)
    # A distractor unlike any object of its class with the odometry alone (it shares its hits).
    unlike_class: bool = False


class ClutterModel:
    """The clutter side of the target for one problem (see the module docstring).

    ``problem`` is the problem with the distractors' prior rows appended: solves of
    associations with distractors must use it (it equals the input for classes).
    """

    def __init__(self, problem: GraphProblem, config: ClutterConfig):
        self.config = config
        self._first_row: int | None = None
        if config.distractor_weight > 0.0:
            floor = config.distractor_floor_stddev_m if config.distractor_floor_stddev_m > 0.0 else NO_FLOOR
            problem, self._first_row = with_extra_priors(problem, *distractor_priors(problem, config), floor)
        self.problem = problem

    def distractor_row(self, measurement: int) -> int:
        """Prior row of a distractor of the class of ``measurement``."""
        if self._first_row is None:
            raise ValueError("the clutter model has no distractors (distractor_weight is 0)")
        return self._first_row + int(self.problem.measurement_label[measurement])

    def distractor_fit(self, measurement_indices: ArrayLike) -> DistractorFit:
        """The slices as one distractor with the odometry alone (:class:`DistractorFit`)."""
        if self._first_row is None:
            raise ValueError("the clutter model has no distractors (distractor_weight is 0)")
        members = np.asarray(measurement_indices, dtype=np.int64)
        row = self.distractor_row(int(members[0]))
        solution = solve_with_backend(self.problem, [members], priors=[row])
        thing = solution.objects[0]
        shape = np.array([thing.location_m[2], *thing.size_m])
        label = int(self.problem.measurement_label[members[0]])
        sigmas = np.abs(shape - self.problem.prior_mean[label, 2:]) / self.problem.prior_stddev[label, 2:]
        return DistractorFit(solution, row, bool(sigmas.max() > UNLIKE_CLASS_SIGMAS))

    def distractor(self, measurement_indices: ArrayLike, misses: MissPrice | None = None) -> Component:
        """The slices as one static distractor with the odometry alone, its missed detections
        priced by ``misses`` (none if not given)."""
        fit = self.distractor_fit(measurement_indices)
        value = fit.solution.log_evidence
        if misses is not None and np.isfinite(value):
            value += misses(fit)
        log_w = math.log(self.config.distractor_weight)
        return Component(DISTRACTOR, log_w, log_w + value, fit.unlike_class)

    def component(self, measurement_indices: ArrayLike, misses: MissPrice | None = None) -> Component:
        """The component that explains a tracklet: the likelier one with the odometry alone,
        a distractor's missed detections priced by ``misses`` (none if not given; module docstring)."""
        w = self.config.distractor_weight
        independent = self.config.log_likelihood(np.size(measurement_indices))
        if w == 0.0:
            return Component(INDEPENDENT, independent, independent)
        distractor = self.distractor(measurement_indices, misses)
        if w == 1.0 or distractor.alone_log_likelihood > math.log1p(-w) + independent:
            return distractor
        return Component(INDEPENDENT, math.log1p(-w) + independent, math.log1p(-w) + independent)
