r"""Missed detections: an object must also explain the images it is absent from.

The paper's likelihood (and the evidence of :mod:`objslam_mapper.graph.solver`) scores the
slices an object owns and nothing else, as if an object were detected exactly where it was
seen. Then two short tracklets far apart in time can together pin a confident *ghost*: on
a rendered office, six slices of a cyan object blurred with a poster behind it, on the
first pass, and eight of the poster alone, 390 images later, made a cyan object where
there was none, which the robot faced in 190 images without ever detecting it.

The detector is modelled instead: in every image, each thing the camera should see is
detected with probability ``P_d`` (``detection.probability``), independently of the other
images and things. A detection costs ``log P_d`` whatever explains it (an object or a
distractor: both are things that are there), so those terms are the same in every
association and drop out (for the slices of independent false alarms, a small bias of
0.36 nats per slice at the default, against the ~20 nats a slice is worth to an object).
What differs is the misses: the likelihood of ``J`` gains, per object and per distractor
(the cylinder it is fitted as),

    n_miss log(1 - P_d),

``n_miss`` the images where it should be seen and has none of its slices. "Should be
seen", at the MAP of ``J`` (:func:`sightings`):

- its predicted angular width is at least ``detection.narrowest_width_rad`` (the detector's
  narrowest blob), and it is no farther than ``detection.max_range_m``;
- its lower edge is below the top of the camera's view, read off the data: the
  ``detection.view_top_quantile`` quantile of every slice's upper edge (a slice of an
  object cut by the edge of the view has its upper edge there);
- nearer objects, distractors and tables do not together cover more than half of its
  silhouette (the rectangle of its bearing interval and its elevations, up to the top of
  the view). Elevations count: a short object in front of a tall one leaves its upper part
  in view, which the detector sees. Tables count: the data contract puts every object whose class
  stands above the floor on a grey table (``detection.table_diameter_m`` across, as tall as
  the object's base), which the detector does not see but which hides what is behind it.
  Without them, two objects of one class standing where one does (a duplicate) hid what is
  behind that place better than the narrower single object, in the images where the real
  table hides it: the target preferred the duplicate by 13-21 nats on ``twins``; with
  them, the best states of unscreened chains with and without it score within a nat.

Narrow things are detected less often. Measured (``objslam eval-detector --min-width-px 0``
on ``office`` seeds 0 and 12, unoccluded objects in full view): recall 0 of 267 below 1 deg of
predicted width, 0.25-0.30 from 1 to 1.5 deg, 0.98-0.995 from 1.5 to 2 deg, 1.00 above (by
range only through the width: 1.00 for the wide objects seen beyond 10 m; on pinhole and
fisheye renders 0, 0.57-0.60 and 0.99 in the same bands). So ``P_d`` is a
function of the predicted width ``w`` (:func:`detection_rate`): the full ``P_d`` from
``detection.min_angular_width_rad`` (2 deg) up, falling linearly to 0 at
``detection.narrowest_width_rad`` (1 deg). A miss at ``w`` costs ``log(1 - P_d(w))``, and a
slice costs ``log(P_d(w) / P_d)`` (its ``log P_d`` is common to every association, as above),
floored at ``log detection.narrow_hit_probability`` (0.01: the width is an estimate) wherever
the thing is in frame, at any width and range. Without the slices' part a thing placed where
it is too narrow to be seen escaped the term altogether: on ``office`` seed 12 two tracklets of
a cyan poster seen from 7.5 m (widths 1.4-3.9 deg) and a fragment of a real object met 11.5 m
away, behind the wall, as a cyan object about 0.75 deg wide from every pose, which paid no
miss, and the target preferred that phantom by 83 nats. A ramp rather than the measured step
because a step at 1.5 deg would charge real objects the full miss where their predicted width
is a little off.

Distractors pay their misses as objects do: otherwise clutter would be an escape from the
term (an object split in two across a loop misses in the images of the other half; as a
distractor it would not), and the chain would clear real objects into it. A flat poster
is not seen from behind, which a cylinder is: such misses make independent false alarms
(no misses) more attractive for it, which keeps it in clutter all the same. What the
visibility test gets wrong (lighting, a table's size, a thing half hidden) shows up as a
few misses of real objects; at the default ``P_d = 0.7`` a miss costs 1.2 nats, a slice an
object owns is worth about 20 to it, so a real object is never lost to them, while a ghost
in view of hundreds of images without a detection pays hundreds of nats.

One exception: a distractor was one clutter tracklet, so a poster seen in several tracklets
was several distractors at one place, each of which would pay a miss in every image where
only the others have slices (clutter tracklets that one distractor explains better together
are now one, :meth:`~objslam_mapper.inference.target.AssociationTarget.clutter_things`;
those that are not, as when their joint fit is worse, still are several). On ``clutter`` a
cyan poster's two tracklets paid 157 and 301 misses more as distractors than as two cyan
objects a metre in front of the wall, and the target mapped the poster twice at P = 1.00.
Distractors of one class whose footprints overlap are therefore fragments of one thing
(:func:`share`): an image where one of them has a slice is no miss for the others, and an
image where several should see the thing counts once. Without the second half, a poster
seen on four passes of a loop as four distractors paid each miss between the passes up to
four times: on a ``loop`` bag 38 misses (46 nats) more in the right map than in one with
every real object a distractor (and the odometry's distance scale 6 % off, which nothing
then pins), which the target preferred by 2 nats; counted once, the right map wins by 40.
A fragment's fit lies only as well as its slices place it, and whether two footprints meet
was a cliff: on ``office`` seed 13 the short middle tracklet of a blue poster (18 slices, seen
head-on from 11 m) was fitted 0.6 m in front of the other two's fits in one state's solve,
touching them, and 0.3 m further in the solve of the state with a real object's four missing
tracklets added, apart, where it paid 351 misses (422 nats). Adding them then cost 34 nats where
it gains 331, and two chains kept the object in two pieces. So an image where a slice of a
fragment of its kind lies over a thing's predicted bearing interval is a hit for it as well
(:func:`fragment_hits`): the rule the distractor's clutter component is chosen by (clutter
module docstring), which a fit's place along its line of sight barely moves.
Only those unlike any object of their class share
(:meth:`~objslam_mapper.inference.target.AssociationTarget.kin`): otherwise a real object's
tracklets could leave it for fragments that pay the misses of one thing with the freedom of
several (on ``clutter`` two real objects did). Objects never share hits: of two objects at
one place one is a duplicate, and its misses are what gives it away.

An option (``detection.distractor_rate_prior`` s > 0, off by default): the same distractors,
unlike any object of their class, are detected at a rate of their own, ``r ~ Beta(s P_d,
s (1 - P_d))``, and pay the beta-binomial marginal of their hits and misses (less the hits'
``log P_d``, see above) instead of ``n_miss log(1 - P_d)``: a poster or a floor patch is seen
from far fewer places than a cylinder of its size, and at P_d a patch seen in 9 of 500 images
pays 600 nats, which made it cheaper as an object. A thing seen about as often as P_d says
pays about the same either way. Given to every distractor it was an escape: on ``clutter``
(seed 1) four of eight real objects went to clutter.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.geometry import wrap_angle
from objslam_mapper.config import DetectionConfig
from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.model.slice_model import BEARING, ELEVATION_BOTTOM, ELEVATION_TOP, WIDTH, predict_reduced

# A gap this wide in the bearings of every slice means the camera does not see all around
# (a perspective or fisheye camera): its view is the rest.
LIMITED_VIEW_GAP_RAD = math.pi / 2


class View(NamedTuple):
    """What the camera sees, read off the data (no camera model in the mapper): elevations
    from ``bottom_rad`` to ``top_rad``, bearings from ``azimuth_lo_rad`` over ``azimuth_span_rad``
    (counter-clockwise; 2 pi: all around)."""

    top_rad: float
    bottom_rad: float = -math.inf
    azimuth_lo_rad: float = -math.pi
    azimuth_span_rad: float = 2.0 * math.pi

    @property
    def all_around(self) -> bool:
        return self.azimuth_span_rad >= 2.0 * math.pi


EVERYWHERE = View(math.inf)


def camera_view(problem: GraphProblem, config: DetectionConfig) -> View:
    """The camera's :class:`View` from the slices: its top is the ``view_top_quantile`` of
    their upper edges (a slice cut by the view's edge ends there). If their left and right
    edges leave a gap wider than LIMITED_VIEW_GAP_RAD, the camera looks one way: its
    bearings are the rest, and its bottom is the other quantile of their lower edges. An
    omnidirectional camera leaves no such gap where objects stand all around; where they do
    not, the view only stops counting misses of things no slice was ever near."""
    if problem.measurement_count == 0:
        return EVERYWHERE
    m = problem.measurements
    top = float(np.quantile(m[:, 3], config.view_top_quantile))
    edges = np.sort(np.mod(np.concatenate([m[:, 0] - 0.5 * m[:, 1], m[:, 0] + 0.5 * m[:, 1]]) + math.pi, 2 * math.pi))
    gaps = np.diff(np.concatenate([edges, edges[:1] + 2 * math.pi]))
    widest = int(np.argmax(gaps))
    if gaps[widest] < LIMITED_VIEW_GAP_RAD:
        return View(top)
    lo = float(wrap_angle(edges[(widest + 1) % len(edges)] - math.pi))
    bottom = float(np.quantile(m[:, 2], 1.0 - config.view_top_quantile))
    return View(top, bottom, lo, float(2 * math.pi - gaps[widest]))


@dataclass(frozen=True)
class Sight:
    """How K things appear from N poses: (N, K) bearing, width, elevations of the lower and
    upper edge and range, and ``in_view`` (valid, wide enough, near enough, below the top of
    the view), before occlusion; ``footprint`` (3, K) is where each stands on the floor (x, y,
    radius, in the map frame); ``in_frame`` (N, K) is ``in_view`` at any width and range,
    where a slice of the thing is charged what its predicted width makes it worth
    (:func:`detection_rate`)."""

    bearing: NDArray[np.float64]
    width: NDArray[np.float64]
    bottom: NDArray[np.float64]
    top: NDArray[np.float64]
    range_m: NDArray[np.float64]
    in_view: NDArray[np.bool_]
    footprint: NDArray[np.float64]
    in_frame: NDArray[np.bool_]

    def columns(self, index: ArrayLike) -> Sight:
        taken = np.asarray(index, dtype=np.int64)
        return Sight(*(getattr(self, f)[:, taken] for f in Sight.__dataclass_fields__))

    @staticmethod
    def none_of(n_poses: int) -> Sight:
        """No things seen from ``n_poses`` poses."""
        empty = np.zeros((n_poses, 0))
        return Sight(
            bearing=empty,
            width=empty,
            bottom=empty,
            top=empty,
            range_m=empty,
            in_view=empty.astype(bool),
            footprint=np.zeros((3, 0)),
            in_frame=empty.astype(bool),
        )

    @staticmethod
    def join(parts: Sequence[Sight]) -> Sight:
        return Sight(*(np.concatenate([getattr(p, f) for p in parts], axis=1) for f in Sight.__dataclass_fields__))


def sight(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    config: DetectionConfig,
    view: View,
) -> Sight:
    """The :class:`Sight` of (K, 5) things (x, y, z_base, diameter, height) from the poses:
    in view where the whole bearing interval is within the view's and the thing reaches
    into its elevations."""
    things = np.asarray(things, dtype=float).reshape(-1, 5)
    poses = np.asarray(map_T_base, dtype=float)
    n, k = len(poses), len(things)
    if k == 0:
        return Sight.none_of(n)
    pred = predict_reduced(
        np.repeat(poses, k, axis=0),
        np.tile(things[:, :3], (n, 1)),
        np.tile(things[:, 3:], (n, 1)),
        problem.mount,
        jacobians=False,
    )
    values = pred.values.reshape(4, n, k)
    dist = pred.range_m.reshape(n, k)
    in_frame = pred.valid.reshape(n, k) & (values[ELEVATION_BOTTOM] < view.top_rad)
    if not view.all_around:
        offset = np.mod(values[BEARING] - view.azimuth_lo_rad, 2 * math.pi)
        half = 0.5 * values[WIDTH]
        in_frame &= (
            (offset >= half) & (offset + half <= view.azimuth_span_rad) & (values[ELEVATION_TOP] > view.bottom_rad)
        )
    in_view = in_frame & (values[WIDTH] >= narrowest_counted_rad(config)) & (dist <= config.max_range_m)
    # What the camera can see of a thing ends at the top of the view.
    top = np.minimum(values[ELEVATION_TOP], view.top_rad)
    footprint = np.vstack([things[:, :2].T, 0.5 * things[:, 3]])
    return Sight(
        values[BEARING],
        values[WIDTH],
        values[ELEVATION_BOTTOM],
        top,
        dist,
        in_view,
        footprint=footprint,
        in_frame=in_frame,
    )


def narrowest_counted_rad(config: DetectionConfig) -> float:
    """The narrowest predicted width at which a thing without a slice counts as missed: where
    its detection rate starts to rise above zero (:func:`detection_rate`)."""
    return min(config.narrowest_width_rad, config.min_angular_width_rad)


def detection_rate(width_rad: NDArray[np.float64], config: DetectionConfig) -> NDArray[np.float64]:
    """The detection probability of a thing of predicted angular width ``width_rad``, as a share
    of ``P_d``: 1 from ``min_angular_width_rad`` up, falling linearly to 0 at
    ``narrowest_width_rad`` (the detector finds no blob narrower), never below
    ``narrow_hit_probability`` (what a slice of a thing predicted too narrow to be seen is
    worth: the width is an estimate). With ``narrowest_width_rad`` at or above the full width,
    a step there."""
    width = np.asarray(width_rad, dtype=float)
    full, narrowest = config.min_angular_width_rad, narrowest_counted_rad(config)
    if full > narrowest:
        rate = np.clip((width - narrowest) / (full - narrowest), 0.0, 1.0)
    else:
        rate = (width >= full).astype(float)
    return np.maximum(rate, config.narrow_hit_probability)


def table_sight(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    on_table: NDArray[np.bool_],
    config: DetectionConfig,
) -> Sight:
    """The tables under (K, 5) ``things`` where ``on_table``, column k under thing k: as wide
    as ``table_diameter_m`` (or the thing, if wider), from the floor to the thing's base.
    They hide what is behind them but are never in view themselves (they are not detected);
    a column without a table is infinitely far, so it hides nothing."""
    things = np.asarray(things, dtype=float).reshape(-1, 5)
    tables = np.zeros_like(things)
    tables[:, :2] = things[:, :2]
    tables[:, 3] = np.maximum(config.table_diameter_m, things[:, 3])
    tables[:, 4] = things[:, 2]
    seen = sight(problem, map_T_base, tables, config, EVERYWHERE)
    absent = ~np.asarray(on_table, dtype=bool) | (config.table_diameter_m <= 0.0)
    return dataclasses.replace(
        seen,
        range_m=np.where(absent, np.inf, seen.range_m),
        in_view=np.zeros_like(seen.in_view),
        in_frame=np.zeros_like(seen.in_frame),
    )


# The share of a thing's silhouette that nearer things cover is measured on a grid of this
# many points per side: occluders overlap each other (a table and the object on it, two
# objects side by side), so their covers do not add up and the union is what counts. A
# column of the grid is one 16-bit word (bit i: elevation point i covered).
_COVER_GRID = 16
_POPCOUNT = np.unpackbits(np.arange(1 << _COVER_GRID, dtype=">u2").view(np.uint8)).reshape(-1, 16).sum(axis=1)


def hidden(rows: Sight, occluders: Sight, config: DetectionConfig) -> NDArray[np.bool_]:
    """(N, R) whether nearer things of ``occluders`` together hide each thing of ``rows``
    where it is in view (False elsewhere): they cover more than ``occlusion_cover`` of its
    silhouette, the rectangle of its bearing interval and its elevations below the top of the
    view. A thing does not hide itself (it is not nearer than itself), nor does anything whose
    footprint overlaps its own: real things do not share floor space (the prior of
    :mod:`objslam_mapper.inference.exclusion`), so of two that do, one is not there, and it
    cannot excuse the other's misses. Without this rule a duplicate hid its original and was
    hidden by it in the images where only one of them had slices, and on forward cameras the
    target preferred duplicates by up to 100 nats."""
    out = np.zeros(rows.in_view.shape, dtype=bool)
    occluders = occluders.columns(np.flatnonzero(np.isfinite(occluders.range_m).any(axis=0)))
    if not occluders.bearing.shape[1]:
        return out
    mine, theirs = rows.footprint, occluders.footprint
    apart = np.hypot(mine[0][:, None] - theirs[0][None, :], mine[1][:, None] - theirs[1][None, :])
    overlapping = apart < mine[2][:, None] + theirs[2][None, :]  # (R, O)
    # Only the (pose, thing) pairs in view matter: (P, O) against every occluder.
    pose, row = np.nonzero(rows.in_view)
    half_width = 0.5 * rows.width[pose, row]
    bottom, top = rows.bottom[pose, row], rows.top[pose, row]
    offset = wrap_angle(occluders.bearing[pose] - rows.bearing[pose, row][:, None])
    occ_half_width = 0.5 * occluders.width[pose]
    candidate = (
        ~overlapping[row]
        & (occluders.range_m[pose] < rows.range_m[pose, row][:, None])
        & (np.abs(offset) < half_width[:, None] + occ_half_width)
        & (occluders.bottom[pose] < top[:, None])
        & (occluders.top[pose] > bottom[:, None])
    )
    # The (pair, occluder) candidates, few per pair: each pair's grid points against each.
    pair, occ = np.nonzero(candidate)
    if not len(pair):
        return out
    unit = (np.arange(_COVER_GRID) + 0.5) / _COVER_GRID
    u = (2.0 * unit - 1.0)[None, :] * half_width[pair, None]
    v = bottom[pair, None] + unit[None, :] * (top - bottom)[pair, None]
    p_pose = pose[pair]
    in_bearing = np.abs(u - offset[pair, occ][:, None]) <= occ_half_width[pair, occ][:, None]
    in_elevation = (v >= occluders.bottom[p_pose, occ][:, None]) & (v <= occluders.top[p_pose, occ][:, None])
    elevation_bits = (in_elevation.astype(np.int64) << np.arange(_COVER_GRID)).sum(axis=1)
    # OR of the candidates' covers per pair: (P, G) words, one per bearing point.
    covered = np.zeros((len(pose), _COVER_GRID), dtype=np.int64)
    column_bits = np.where(in_bearing, elevation_bits[:, None], 0)
    np.bitwise_or.at(covered, pair, column_bits)
    share = _POPCOUNT[covered].sum(axis=1) / float(_COVER_GRID * _COVER_GRID)
    out[pose, row] = share > config.occlusion_cover
    return out


def visible(rows: Sight, occluders: Sight, config: DetectionConfig) -> NDArray[np.bool_]:
    """(N, R) whether each thing of ``rows`` is in view and hidden by no nearer ones of ``occluders``."""
    return rows.in_view & ~hidden(rows, occluders, config)


def hit_matrix(problem: GraphProblem, n_poses: int, groups: Sequence[NDArray[np.int64]]) -> NDArray[np.bool_]:
    """(N, R) whether image n holds a slice of group r (measurement indices)."""
    hit = np.zeros((n_poses, len(groups)), dtype=bool)
    for r, group in enumerate(groups):
        hit[problem.measurement_pose[np.asarray(group, dtype=np.int64)], r] = True
    return hit


@dataclass(frozen=True)
class Sightings:
    """K things with their slices, from N poses: the :class:`Sight`, the tables under them
    (:func:`table_sight`), where the others and the tables hide each one (``hidden``, (N, K)),
    where each has a slice, or a fragment of its thing has (``hit``, (N, K)), where a
    fragment before it already counts the image (``repeated``, (N, K); :func:`share`), and
    where a slice of its own is charged its predicted width's detection rate (``charged``,
    (N, K): in frame, not repeated)."""

    sight: Sight
    tables: Sight
    hidden: NDArray[np.bool_]
    hit: NDArray[np.bool_]
    kin: NDArray[np.int64]  # (K,) which share their hits and are detected at a rate of their own (-1: none)
    repeated: NDArray[np.bool_]
    charged: NDArray[np.bool_]

    @property
    def visible(self) -> NDArray[np.bool_]:
        """(N, K) images where a thing is in view and not hidden."""
        return self.sight.in_view & ~self.hidden

    @property
    def should(self) -> NDArray[np.bool_]:
        """(N, K) images where a thing should be seen and counts: visible, and no fragment of
        its thing before it counts the image already."""
        return self.visible & ~self.repeated

    @property
    def missed(self) -> NDArray[np.bool_]:
        """(N, K) images where a thing should be seen and has no slice."""
        return self.should & ~self.hit

    def terms(self, config: DetectionConfig, columns: Sequence[int] | None = None) -> MissTerms:
        """The :class:`MissTerms` of the things of ``columns`` (default: all)."""
        index = slice(None) if columns is None else list(columns)
        return MissTerms.of(
            self.should[:, index],
            self.hit[:, index],
            self.kin[index] >= 0,
            config,
            width_rad=self.sight.width[:, index],
            charged=self.charged[:, index],
        )

    def occluders(self, index: Sequence[int]) -> Sight:
        """The things of ``index`` and their tables, as occluders of others."""
        return Sight.join([self.sight.columns(index), self.tables.columns(index)])


def share(
    hit: NDArray[np.bool_], should: NDArray[np.bool_], footprint: NDArray[np.float64], kin: NDArray[np.int64]
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(N, K) ``hit`` and ``should`` of K things where those of one non-negative ``kin`` (K,)
    whose ``footprint`` (3, K) overlap are fragments of one thing (module docstring): each
    has the hits of the others, and an image where several should be seen counts for the
    first of them only. Things of ``kin`` -1 keep their own."""
    kin = np.asarray(kin, dtype=np.int64)
    members = np.flatnonzero(kin >= 0)
    if len(members) < 2:
        return hit, should
    fp = footprint[:, members]
    apart = np.hypot(fp[0][:, None] - fp[0][None, :], fp[1][:, None] - fp[1][None, :])
    sharing = (apart < fp[2][:, None] + fp[2][None, :]) & (kin[members][:, None] == kin[members][None, :])
    out_hit, out_should = hit.copy(), should.copy()
    out_hit[:, members] = (hit[:, members].astype(np.int64) @ sharing.astype(np.int64)) > 0
    earlier = np.triu(sharing, k=1).astype(np.int64)  # [j, k]: j < k are fragments of one thing
    out_should[:, members] &= (should[:, members].astype(np.int64) @ earlier) == 0
    return out_hit, out_should


class Counts(NamedTuple):
    """(N, K) what the detection term counts of K things (:class:`Sightings`)."""

    hit: NDArray[np.bool_]
    should: NDArray[np.bool_]
    repeated: NDArray[np.bool_]
    charged: NDArray[np.bool_]


def lies_over(
    bearing_rad: NDArray[np.float64],
    width_rad: NDArray[np.float64],
    predicted_bearing_rad: NDArray[np.float64],
    predicted_width_rad: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Whether slices (broadcast against the predictions) overlap a thing's predicted bearing
    interval: their centres closer than half the two widths."""
    off = np.abs(wrap_angle(bearing_rad - predicted_bearing_rad))
    return off < 0.5 * (width_rad + predicted_width_rad)


def fragment_hits(
    problem: GraphProblem, seen: Sight, groups: Sequence[NDArray[np.int64]], kin: NDArray[np.int64]
) -> NDArray[np.bool_]:
    """(N, K) where a slice of another thing of one non-negative ``kin`` lies over a thing's
    predicted bearing interval (within half the two widths): a fragment of its thing seen
    where it is (module docstring). Things of ``kin`` -1 have none."""
    over = np.zeros(seen.bearing.shape, dtype=bool)
    kin = np.asarray(kin, dtype=np.int64)
    measured = np.asarray(problem.measurements)
    for row in np.unique(kin[kin >= 0]):
        columns = np.flatnonzero(kin == row)
        if len(columns) < 2:
            continue
        for j in columns:
            slices = np.asarray(groups[int(j)], dtype=np.int64)
            pose = problem.measurement_pose[slices]
            others = columns[columns != j]
            near = lies_over(
                measured[slices, BEARING][:, None],
                measured[slices, WIDTH][:, None],
                seen.bearing[pose][:, others],
                seen.width[pose][:, others],
            )
            at, of = np.nonzero(near)
            over[pose[at], others[of]] = True
    return over


def count(
    problem: GraphProblem,
    groups: Sequence[NDArray[np.int64]],
    own_should: NDArray[np.bool_],
    seen: Sight,
    kin: NDArray[np.int64],
) -> Counts:
    """The :class:`Counts` of the K things of ``seen``, whose slices are ``groups``
    (measurement indices), from where each is visible (``own_should``): fragments of one
    thing share their hits and images (:func:`share`), an image where a fragment has a slice
    over a thing's predicted bearing interval is a hit for it (:func:`fragment_hits`), and its
    own slices are charged where it is in frame and the image is not a fragment's before it.
    The target's sightings and the screen's changed groups both count through here, so that
    they cannot count differently."""
    own_hit = hit_matrix(problem, len(own_should), groups)
    hit, should = share(own_hit, own_should, seen.footprint, kin)
    hit |= fragment_hits(problem, seen, groups, kin)
    repeated = own_should & ~should
    return Counts(hit, should, repeated, own_hit & seen.in_frame & ~repeated)


def sightings(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    groups: Sequence[NDArray[np.int64]],
    config: DetectionConfig,
    view: View,
    *,
    on_table: NDArray[np.bool_] | None = None,
    kin: NDArray[np.int64] | None = None,
) -> Sightings:
    """The :class:`Sightings` of (K, 5) ``things`` and their ``groups`` (measurement indices);
    ``on_table`` (K,) says which stand on a table (default: none), ``kin`` (K,) which share
    their hits and misses (:func:`share`) and are detected at a rate of their own (:class:`MissTerms`;
    default: none)."""
    seen = sight(problem, map_T_base, things, config, view)
    k = seen.bearing.shape[1]
    tables = table_sight(problem, map_T_base, things, np.zeros(k, bool) if on_table is None else on_table, config)
    covered = hidden(seen, Sight.join([seen, tables]), config)
    kin = np.full(k, -1, dtype=np.int64) if kin is None else np.asarray(kin, dtype=np.int64)
    counts = count(problem, groups, seen.in_view & ~covered, seen, kin)
    return Sightings(seen, tables, covered, counts.hit, kin, repeated=counts.repeated, charged=counts.charged)


def miss_count_log_likelihood(n_miss: int, config: DetectionConfig) -> float:
    """``n_miss log(1 - P_d)``."""
    return n_miss * math.log1p(-config.probability)


class MissTerms(NamedTuple):
    """The detection term of some things, in parts that add and subtract exactly: the misses
    of the things detected at the full ``P_d`` (a count), the summed terms of those detected at
    a rate of their own (module docstring), and the terms of narrow things' misses and slices
    (:func:`detection_rate`)."""

    misses: int
    own_rate_log_likelihood: float = 0.0
    width_log_likelihood: float = 0.0

    @staticmethod
    def of(
        should: NDArray[np.bool_],
        hit: NDArray[np.bool_],
        own_rate: NDArray[np.bool_],
        config: DetectionConfig,
        *,
        width_rad: NDArray[np.float64] | None = None,
        charged: NDArray[np.bool_] | None = None,
    ) -> MissTerms:
        """The terms of K things: ``should`` (N, K) be seen, ``hit`` (N, K) have a slice,
        ``own_rate`` (K,) detected at a rate of their own (ignored unless
        ``config.distractor_rate_prior`` > 0); ``width_rad`` (N, K) their predicted widths
        (default: wide) and ``charged`` (N, K) where their own slices are charged their width's
        detection rate (default: nowhere)."""
        missed = should & ~hit
        own = np.asarray(own_rate, dtype=bool) & (config.distractor_rate_prior > 0.0)
        full_missed, narrow_value = missed, 0.0
        if width_rad is not None:
            rate = detection_rate(width_rad, config)
            partial = rate < 1.0
            full_missed = missed & ~partial
            narrow_misses = missed & partial
            narrow_misses[:, own] = False
            narrow_value = float(np.sum(np.log1p(-config.probability * rate[narrow_misses])))
            if charged is not None:
                narrow_value += float(np.sum(np.log(rate[charged & partial])))
        if not own.any():
            return MissTerms(int(np.count_nonzero(full_missed)), 0.0, narrow_value)
        hits = np.count_nonzero(should[:, own] & hit[:, own], axis=0)
        misses = np.count_nonzero(missed[:, own], axis=0)
        own_value = sum(own_rate_log_likelihood(int(h), int(m), config) for h, m in zip(hits, misses, strict=True))
        return MissTerms(int(np.count_nonzero(full_missed[:, ~own])), own_value, narrow_value)

    def __sub__(self, other: object) -> MissTerms:
        assert isinstance(other, MissTerms)
        return MissTerms(
            self.misses - other.misses,
            self.own_rate_log_likelihood - other.own_rate_log_likelihood,
            self.width_log_likelihood - other.width_log_likelihood,
        )

    def log_likelihood(self, config: DetectionConfig) -> float:
        return miss_count_log_likelihood(self.misses, config) + self.own_rate_log_likelihood + self.width_log_likelihood


def own_rate_log_likelihood(hits: int, misses: int, config: DetectionConfig) -> float:
    """The detection term of a thing detected at an unknown rate ``r ~ Beta(s P_d, s (1 - P_d))``,
    ``s`` = ``distractor_rate_prior``: the beta-binomial marginal of its ``hits`` and ``misses``,
    less ``hits log P_d`` (what a detection costs in every association; module docstring)."""
    a = config.distractor_rate_prior * config.probability
    b = config.distractor_rate_prior - a
    return _log_beta(hits + a, misses + b) - _log_beta(a, b) - hits * math.log(config.probability)


def _log_beta(a: float, b: float) -> float:
    return math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)


def detection_log_likelihood(
    problem: GraphProblem,
    map_T_base: NDArray[np.float64],
    things: NDArray[np.float64],
    groups: Sequence[NDArray[np.int64]],
    config: DetectionConfig,
    view: View,
    *,
    on_table: NDArray[np.bool_] | None = None,
) -> float:
    """``sum of n_miss log(1 - P_d)`` over ``things`` (K, 5) and their ``groups``
    (measurement indices; module docstring), ``on_table`` as for :func:`sightings`."""
    if not config.enabled or not len(groups):
        return 0.0
    seen = sightings(problem, map_T_base, things, groups, config, view, on_table=on_table)
    return seen.terms(config).log_likelihood(config)
