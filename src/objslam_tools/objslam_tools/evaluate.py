"""Scoring a built map against a simulated bag's ground truth (``objslam eval``).

Procedure:

1. Align frames. The map lives in the ``odom`` frame of ``/odom``, the ground truth in the
   frame of ``/ground_truth/odom``. ``gt_T_map`` is the least-squares SE(2) fit of the map's
   trajectory to the ground-truth trajectory interpolated at the map's stamps; the
   trajectory ATE is the RMSE of the xy residuals after that fit. The raw odometry gets
   the same procedure at the same stamps, so the two ATEs compare like for like.
2. Match objects per class: Hungarian assignment on xy distance (in the ground-truth
   frame) with a gate (default 0.5 m). Unmatched map objects are false positives, unmatched
   real objects misses. A false positive within the gate of a same-class distractor's
   footprint is a "distractor that ended as an object". Recall is reported twice: over all
   real objects, and over the objects the camera saw (:mod:`objslam_tools.seen`: in view,
   unhidden, in at least 10 images), which is what a camera that does not see all around
   can be asked for.
3. Errors of matched objects: xy distance, |z_base| error, diameter and height errors, and
   the NEES of the position using the map's ``position_covariance`` (rotated into the
   ground-truth frame). The mean NEES over n matches is compared with the two-sided 95 %
   band of chi-square(n * dof) / n: below the band the covariances are too large
   (pessimistic), above it too small (overconfident). The alignment's own error is not in
   the covariance, so a small excess is expected.

Everything is plain data; :func:`format_report` and :func:`format_table` render it for a
terminal, :meth:`MapScore.to_dict` for ``--json``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from objslam_common.geometry import rotation
from objslam_mapper.map_file import BuiltMap, MappedObject
from objslam_tools.bag import GROUND_TRUTH_ODOM_TOPIC, ODOM_TOPIC, open_bag
from objslam_tools.errors import UserError
from objslam_tools.ground_truth import Distractor, GroundTruth, load_ground_truth
from objslam_tools.seen import images_seen, seen_ids
from objslam_tools.trajectory import PoseTrack, fit_se2, position_rmse, transform_poses

logger = logging.getLogger(__name__)

DEFAULT_GATE_M = 0.5
NEES_CONFIDENCE = 0.95


@dataclass(frozen=True)
class Reference:
    """What a map is scored against: ground truth of one bag (all in the ground-truth frame)."""

    ground_truth: GroundTruth
    ground_truth_track: PoseTrack  # /ground_truth/odom
    odometry_track: PoseTrack | None = None  # /odom, for the raw odometry's ATE
    name: str = ""
    images_seen: dict[int, int] | None = None  # per real object, the images that saw it (objslam_tools.seen)


def load_reference(bag_path: str | Path) -> Reference:
    """Ground truth, ground-truth trajectory and raw odometry of a simulated bag (UserError if absent)."""
    bag = open_bag(bag_path)
    truth = load_ground_truth(bag.directory)
    if not bag.has_topic(GROUND_TRUTH_ODOM_TOPIC):
        raise UserError(f"bag {bag.path} has no {GROUND_TRUTH_ODOM_TOPIC}: cannot align a map to its ground truth")
    gt_track = bag.read_odometry(GROUND_TRUTH_ODOM_TOPIC)
    odom = bag.read_odometry(ODOM_TOPIC) if bag.has_topic(ODOM_TOPIC) else None
    try:
        seen = images_seen(bag, truth, gt_track)
    except UserError as exc:  # no camera info or images: which objects were seen is not known
        logger.info("recall over the objects the camera saw is not known: %s", exc)
        seen = None
    return Reference(truth, gt_track, odom, name=bag.path.name, images_seen=seen)


@dataclass(frozen=True)
class Alignment:
    """gt_T_map and how well the trajectories agree after it."""

    gt_T_map: NDArray[np.float64]  # (x, y, theta)
    ate_m: float  # RMSE of xy after alignment
    pose_count: int

    def to_ground_truth(self, map_xy: ArrayLike) -> NDArray[np.float64]:
        pts = np.atleast_2d(np.asarray(map_xy, dtype=float))
        return pts @ rotation(self.gt_T_map[2]).T + self.gt_T_map[:2]

    def to_map(self, gt_xy: ArrayLike) -> NDArray[np.float64]:
        pts = np.atleast_2d(np.asarray(gt_xy, dtype=float))
        return (pts - self.gt_T_map[:2]) @ rotation(self.gt_T_map[2])


def align_track(estimate: PoseTrack, ground_truth: PoseTrack, what: str = "trajectory") -> Alignment:
    """Fit gt_T_estimate on the estimate's stamps that the ground truth covers."""
    covered = ground_truth.covers(estimate.stamps_ns)
    if covered.sum() < 2:
        raise UserError(
            f"the {what} has {int(covered.sum())} poses within the ground truth's time span "
            f"(need 2): is it from another bag?"
        )
    est_xy = estimate.poses[covered, :2]
    gt_xy = ground_truth.interpolate(estimate.stamps_ns[covered])[:, :2]
    gt_T_est = fit_se2(est_xy, gt_xy)
    aligned = transform_poses(gt_T_est, estimate.poses[covered])
    return Alignment(gt_T_est, position_rmse(aligned[:, :2], gt_xy), int(covered.sum()))


def map_track(built_map: BuiltMap) -> PoseTrack:
    return PoseTrack(np.array([p.stamp_ns for p in built_map.trajectory], dtype=np.int64), built_map.trajectory_array())


def align_map(built_map: BuiltMap, ground_truth_track: PoseTrack) -> Alignment:
    """gt_T_map from the map's trajectory (UserError if it has fewer than two usable poses)."""
    if len(built_map.trajectory) < 2:
        raise UserError("the map has no trajectory (need at least 2 poses to align it to the ground truth)")
    return align_track(map_track(built_map), ground_truth_track, "map's trajectory")


@dataclass(frozen=True)
class ObjectMatch:
    map_id: int
    truth_id: int
    label: str
    existence_probability: float
    xy_error_m: float
    z_error_m: float  # |z_base error|
    diameter_error_m: float  # signed, map - truth
    height_error_m: float  # signed, map - truth
    nees_xy: float  # NaN if the map carries no usable covariance
    nees_xyz: float


@dataclass(frozen=True)
class FalsePositive:
    map_id: int
    label: str
    existence_probability: float
    position_m: tuple[float, float, float]  # in the ground-truth frame
    nearest_truth_m: float  # xy distance to the nearest real object of the class (inf if none)
    distractor_id: int | None  # same-class distractor whose footprint is within the gate
    distractor_kind: str | None


@dataclass(frozen=True)
class Miss:
    truth_id: int
    label: str
    position_m: tuple[float, float, float]
    rejected_map_id: int | None  # a rejected map object of the class within the gate: found but not believed
    images_seen: int | None = None  # images that saw it whole and unhidden (objslam_tools.seen)


@dataclass(frozen=True)
class NeesSummary:
    dof: int
    count: int
    mean: float
    band: tuple[float, float]  # 95 % band of the mean NEES

    @property
    def verdict(self) -> str:
        if self.count == 0 or not math.isfinite(self.mean):
            return "n/a"
        if self.mean < self.band[0]:
            return "pessimistic"
        if self.mean > self.band[1]:
            return "overconfident"
        return "consistent"


@dataclass(frozen=True)
class MapScore:
    name: str
    gate_m: float
    truth_count: int
    map_count: int
    rejected_count: int
    matches: tuple[ObjectMatch, ...]
    false_positives: tuple[FalsePositive, ...]
    misses: tuple[Miss, ...]
    alignment: Alignment
    odometry_ate_m: float | None
    nees_xy: NeesSummary
    nees_xyz: NeesSummary
    diagnostics: dict[str, Any] = field(default_factory=dict)
    seen: frozenset[int] | None = None  # real objects the camera saw (None: not known)
    overlapping_pairs: int = 0  # pairs of map objects of one class whose footprints overlap (overlapping_pairs)

    @property
    def precision(self) -> float:
        return len(self.matches) / self.map_count if self.map_count else float("nan")

    @property
    def recall(self) -> float:
        return len(self.matches) / self.truth_count if self.truth_count else float("nan")

    @property
    def recall_seen(self) -> float:
        """Recall over the real objects the camera saw (NaN if none was, or it is not known)."""
        if not self.seen:
            return float("nan")
        return sum(1 for m in self.matches if m.truth_id in self.seen) / len(self.seen)

    def _errors(self, name: str) -> NDArray[np.float64]:
        return np.array([getattr(m, name) for m in self.matches], dtype=float)

    @property
    def distractor_objects(self) -> tuple[FalsePositive, ...]:
        return tuple(fp for fp in self.false_positives if fp.distractor_id is not None)

    def metrics(self) -> dict[str, float | int | None]:
        """Flat scalar metrics, the rows of the side-by-side table and of ``--json``."""
        xy = self._errors("xy_error_m")

        def stat(values: NDArray[np.float64], fn) -> float | None:
            return float(fn(values)) if len(values) else None

        return {
            "truth_objects": self.truth_count,
            "map_objects": self.map_count,
            "rejected_objects": self.rejected_count,
            "true_positives": len(self.matches),
            "false_positives": len(self.false_positives),
            "misses": len(self.misses),
            "precision": _none_if_nan(self.precision),
            "recall": _none_if_nan(self.recall),
            "seen_objects": None if self.seen is None else len(self.seen),
            "recall_seen": _none_if_nan(self.recall_seen),
            "xy_error_mean_m": stat(xy, np.mean),
            "xy_error_median_m": stat(xy, np.median),
            "xy_error_max_m": stat(xy, np.max),
            "z_error_mean_m": stat(self._errors("z_error_m"), np.mean),
            "diameter_error_mean_m": stat(np.abs(self._errors("diameter_error_m")), np.mean),
            "height_error_mean_m": stat(np.abs(self._errors("height_error_m")), np.mean),
            "nees_xy_mean": _none_if_nan(self.nees_xy.mean),
            "nees_xy_band_low": self.nees_xy.band[0] if self.nees_xy.count else None,
            "nees_xy_band_high": self.nees_xy.band[1] if self.nees_xy.count else None,
            "nees_xyz_mean": _none_if_nan(self.nees_xyz.mean),
            "nees_xyz_band_low": self.nees_xyz.band[0] if self.nees_xyz.count else None,
            "nees_xyz_band_high": self.nees_xyz.band[1] if self.nees_xyz.count else None,
            "trajectory_ate_m": self.alignment.ate_m,
            "odometry_ate_m": self.odometry_ate_m,
            "distractors_as_objects": len(self.distractor_objects),
            "misses_rejected": sum(1 for m in self.misses if m.rejected_map_id is not None),
            "overlapping_pairs": self.overlapping_pairs,
        }

    def to_dict(self) -> dict[str, Any]:
        def rec(obj: Any) -> dict[str, Any]:
            return {k: _jsonable(v) for k, v in obj.__dict__.items()}

        return {
            "name": self.name,
            "gate_m": self.gate_m,
            "metrics": self.metrics(),
            "nees_xy": {**rec(self.nees_xy), "verdict": self.nees_xy.verdict},
            "nees_xyz": {**rec(self.nees_xyz), "verdict": self.nees_xyz.verdict},
            "gt_T_map": [float(v) for v in self.alignment.gt_T_map],
            "aligned_pose_count": self.alignment.pose_count,
            "matches": [rec(m) for m in self.matches],
            "false_positives": [rec(fp) for fp in self.false_positives],
            "misses": [rec(m) for m in self.misses],
            "diagnostics": _jsonable(self.diagnostics),
        }


def _none_if_nan(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return _none_if_nan(float(value))
    if isinstance(value, np.generic):
        return value.item()
    return value


def _footprint_distance_m(distractor: Distractor, xy: NDArray[np.float64]) -> float:
    """xy distance from a point to a distractor's footprint (vertical: a segment; on the floor: a rectangle)."""
    corners = distractor.corners_m()[:, :2]
    if not distractor.is_vertical:
        # Inside the rectangle: the edge normals all point away from the point.
        edges = np.roll(corners, -1, axis=0) - corners
        cross = edges[:, 0] * (xy[1] - corners[:, 1]) - edges[:, 1] * (xy[0] - corners[:, 0])
        if np.all(cross >= 0) or np.all(cross <= 0):
            return 0.0
    best = math.inf
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        ab = b - a
        denom = float(ab @ ab)
        t = 0.0 if denom == 0 else float(np.clip((xy - a) @ ab / denom, 0.0, 1.0))
        best = min(best, float(np.linalg.norm(xy - (a + t * ab))))
    return best


def _rotated_covariance(obj: MappedObject, theta: float) -> NDArray[np.float64]:
    rot = np.eye(3)
    rot[:2, :2] = rotation(theta)
    cov = np.asarray(obj.position_covariance, dtype=float)
    return rot @ cov @ rot.T


def _nees(error: NDArray[np.float64], cov: NDArray[np.float64]) -> float:
    """e^T C^-1 e, NaN when C is not positive definite (a map without covariances)."""
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return float("nan")
    z = np.linalg.solve(chol, error)
    return float(z @ z)


def nees_summary(values: Sequence[float], dof: int, confidence: float = NEES_CONFIDENCE) -> NeesSummary:
    """Mean NEES and the two-sided band of chi2(n dof)/n that it falls in with probability ``confidence``."""
    finite = np.array([v for v in values if math.isfinite(v)], dtype=float)
    n = len(finite)
    if n == 0:
        return NeesSummary(dof, 0, float("nan"), (float("nan"), float("nan")))
    tail = (1.0 - confidence) / 2.0
    band = (float(chi2.ppf(tail, n * dof) / n), float(chi2.ppf(1.0 - tail, n * dof) / n))
    return NeesSummary(dof, n, float(finite.mean()), band)


def _assign(cost: NDArray[np.float64], gate_m: float) -> list[tuple[int, int]]:
    """Minimum-total-distance pairs (row, col) with distance within the gate."""
    if cost.size == 0:
        return []
    # Pairs beyond the gate may not be chosen at all; a big finite cost keeps the problem feasible.
    big = 1e6
    gated = np.where(cost <= gate_m, cost, big)
    rows, cols = linear_sum_assignment(gated)
    return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if cost[r, c] <= gate_m]


def score_map(built_map: BuiltMap, reference: Reference, gate_m: float = DEFAULT_GATE_M, name: str = "") -> MapScore:
    """Score one map against a reference (see the module docstring)."""
    if gate_m <= 0:
        raise UserError(f"the match gate must be positive, got {gate_m}")
    alignment = align_map(built_map, reference.ground_truth_track)
    odometry_ate = None
    if reference.odometry_track is not None and len(reference.odometry_track):
        # The raw odometry at the map's own stamps: same poses in time, same alignment procedure.
        stamps = map_track(built_map).stamps_ns
        stamps = stamps[reference.odometry_track.covers(stamps)]
        if len(stamps) >= 2:
            odom_at = PoseTrack(stamps, reference.odometry_track.interpolate(stamps))
            odometry_ate = align_track(odom_at, reference.ground_truth_track, "odometry").ate_m

    truth = reference.ground_truth
    theta = float(alignment.gt_T_map[2])

    def in_gt(obj: MappedObject) -> NDArray[np.float64]:
        xy = alignment.to_ground_truth(obj.position_m[:2])[0]
        return np.array([xy[0], xy[1], obj.position_m[2]])

    map_pos = {o.id: in_gt(o) for o in built_map.objects}
    rejected_pos = {o.id: in_gt(o) for o in built_map.rejected}
    truth_pos = np.array([t.position_m for t in truth.objects], dtype=float).reshape(-1, 3)

    matches: list[ObjectMatch] = []
    false_positives: list[FalsePositive] = []
    misses: list[Miss] = []
    labels = sorted({o.label for o in built_map.objects} | {t.label for t in truth.objects})
    for label in labels:
        objs = [o for o in built_map.objects if o.label == label]
        truths = [i for i, t in enumerate(truth.objects) if t.label == label]
        cost = np.array(
            [[float(np.linalg.norm(map_pos[o.id][:2] - truth_pos[i, :2])) for i in truths] for o in objs]
        ).reshape(len(objs), len(truths))
        pairs = _assign(cost, gate_m)
        matched_objs = {r for r, _ in pairs}
        matched_truths = {c for _, c in pairs}
        for r, c in pairs:
            obj, t = objs[r], truth.objects[truths[c]]
            error = map_pos[obj.id] - truth_pos[truths[c]]
            cov = _rotated_covariance(obj, theta)
            matches.append(
                ObjectMatch(
                    map_id=obj.id,
                    truth_id=t.id,
                    label=label,
                    existence_probability=obj.existence_probability,
                    xy_error_m=float(np.linalg.norm(error[:2])),
                    z_error_m=float(abs(error[2])),
                    diameter_error_m=float(obj.size_m[0] - t.size_m[0]),
                    height_error_m=float(obj.size_m[1] - t.size_m[1]),
                    nees_xy=_nees(error[:2], cov[:2, :2]),
                    nees_xyz=_nees(error, cov),
                )
            )
        for r, obj in enumerate(objs):
            if r in matched_objs:
                continue
            xy = map_pos[obj.id][:2]
            nearest = float(cost[r].min()) if len(truths) else math.inf
            distractor = _nearest_distractor(truth.distractors, label, xy, gate_m)
            false_positives.append(
                FalsePositive(
                    map_id=obj.id,
                    label=label,
                    existence_probability=obj.existence_probability,
                    position_m=tuple(float(v) for v in map_pos[obj.id]),  # type: ignore[arg-type]
                    nearest_truth_m=nearest,
                    distractor_id=None if distractor is None else distractor.id,
                    distractor_kind=None if distractor is None else distractor.kind,
                )
            )
        rejected = [o for o in built_map.rejected if o.label == label]
        for c, i in enumerate(truths):
            if c in matched_truths:
                continue
            near = [
                (float(np.linalg.norm(rejected_pos[o.id][:2] - truth_pos[i, :2])), o.id)
                for o in rejected
                if np.linalg.norm(rejected_pos[o.id][:2] - truth_pos[i, :2]) <= gate_m
            ]
            t = truth.objects[i]
            seen_in = None if reference.images_seen is None else reference.images_seen.get(t.id, 0)
            misses.append(Miss(t.id, label, t.position_m, min(near)[1] if near else None, seen_in))

    return MapScore(
        name=name,
        gate_m=gate_m,
        truth_count=len(truth.objects),
        map_count=len(built_map.objects),
        rejected_count=len(built_map.rejected),
        matches=tuple(matches),
        false_positives=tuple(false_positives),
        misses=tuple(misses),
        alignment=alignment,
        odometry_ate_m=odometry_ate,
        nees_xy=nees_summary([m.nees_xy for m in matches], 2),
        nees_xyz=nees_summary([m.nees_xyz for m in matches], 3),
        diagnostics=dict(built_map.diagnostics),
        seen=None if reference.images_seen is None else seen_ids(reference.images_seen),
        overlapping_pairs=overlapping_pairs(built_map.objects),
    )


def overlapping_pairs(objects: Sequence[MappedObject]) -> int:
    """Pairs of ``objects`` of one class closer than their diameters (footprints overlap): one of
    each pair is a duplicate, as real objects do not share floor space. Counted on the reported
    objects (P(ID|Z) > 1/2), so it must be 0."""
    count = 0
    for i, a in enumerate(objects):
        for b in objects[i + 1 :]:
            apart = math.hypot(a.position_m[0] - b.position_m[0], a.position_m[1] - b.position_m[1])
            count += a.label == b.label and apart < 0.5 * (a.size_m[0] + b.size_m[0])
    return count


def _nearest_distractor(
    distractors: Sequence[Distractor], label: str, xy: NDArray[np.float64], gate_m: float
) -> Distractor | None:
    scored = [(_footprint_distance_m(d, xy), d.id, d) for d in distractors if d.label == label]
    scored = [s for s in scored if s[0] <= gate_m]
    return min(scored, key=lambda s: (s[0], s[1]))[2] if scored else None


# ---------------------------------------------------------------- rendering


_ROWS: tuple[tuple[str, str, str], ...] = (
    # metric key, row title, format
    ("truth_objects", "real objects", "d"),
    ("map_objects", "map objects", "d"),
    ("rejected_objects", "rejected (P<=1/2)", "d"),
    ("true_positives", "matched", "d"),
    ("false_positives", "false positives", "d"),
    ("misses", "misses", "d"),
    ("precision", "precision", ".3f"),
    ("recall", "recall (all real objects)", ".3f"),
    ("seen_objects", "objects the camera saw", "d"),
    ("recall_seen", "recall (objects it saw)", ".3f"),
    ("xy_error_mean_m", "xy error mean [m]", ".3f"),
    ("xy_error_median_m", "xy error median [m]", ".3f"),
    ("xy_error_max_m", "xy error max [m]", ".3f"),
    ("z_error_mean_m", "z error mean [m]", ".3f"),
    ("diameter_error_mean_m", "diameter error mean [m]", ".3f"),
    ("height_error_mean_m", "height error mean [m]", ".3f"),
    ("nees_xy", "NEES xy (dof 2) [95% band]", ""),
    ("nees_xyz", "NEES xyz (dof 3) [95% band]", ""),
    ("trajectory_ate_m", "trajectory ATE [m]", ".3f"),
    ("odometry_ate_m", "raw odometry ATE [m]", ".3f"),
    ("distractors_as_objects", "distractors as objects", "d"),
    ("misses_rejected", "misses found but rejected", "d"),
    ("overlapping_pairs", "overlapping pairs (duplicates)", "d"),
)


def _cell(score: MapScore, key: str, fmt: str) -> str:
    if key in ("nees_xy", "nees_xyz"):
        s = score.nees_xy if key == "nees_xy" else score.nees_xyz
        if s.verdict == "n/a":
            return "-"
        return f"{s.mean:.2f} [{s.band[0]:.2f}, {s.band[1]:.2f}] {s.verdict}"
    value = score.metrics()[key]
    return "-" if value is None else format(value, fmt)


def format_table(scores: Sequence[MapScore]) -> str:
    """Metrics side by side, one column per map."""
    header = ["", *[s.name or f"map {i + 1}" for i, s in enumerate(scores)]]
    rows = [header] + [[title, *[_cell(s, key, fmt) for s in scores]] for key, title, fmt in _ROWS]
    widths = [max(len(r[c]) for r in rows) for c in range(len(header))]
    lines = []
    for k, row in enumerate(rows):
        cells = [row[0].ljust(widths[0])] + [cell.rjust(w) for cell, w in zip(row[1:], widths[1:], strict=True)]
        lines.append("  ".join(cells).rstrip())
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def format_details(score: MapScore) -> str:
    """Per-object lists: false positives (with P(exists)), misses, matches."""
    out = []
    title = score.name or "map"
    g = score.alignment.gt_T_map
    out.append(
        f"{title}: aligned on {score.alignment.pose_count} poses, "
        f"gt_T_map = ({g[0]:.3f} m, {g[1]:.3f} m, {math.degrees(g[2]):.1f} deg); gate {score.gate_m:.2f} m"
    )
    if score.false_positives:
        out.append("  false positives (ground-truth frame):")
        for fp in sorted(score.false_positives, key=lambda f: -f.existence_probability):
            why = f"  <- {fp.distractor_kind} distractor {fp.distractor_id}" if fp.distractor_id is not None else ""
            near = f"{fp.nearest_truth_m:.2f} m" if math.isfinite(fp.nearest_truth_m) else "none"
            x, y, z = fp.position_m
            out.append(
                f"    id {fp.map_id:>3} {fp.label:<7} P={fp.existence_probability:.2f} "
                f"at ({x:6.2f}, {y:6.2f}, {z:4.2f}), nearest real {fp.label}: {near}{why}"
            )
    if score.misses:
        out.append("  missed real objects:")
        for m in score.misses:
            x, y, z = m.position_m
            why = f"  (rejected map object {m.rejected_map_id} is there)" if m.rejected_map_id is not None else ""
            if m.images_seen is not None:
                why += f"  seen whole in {m.images_seen} images"
            out.append(f"    truth {m.truth_id:>3} {m.label:<7} at ({x:6.2f}, {y:6.2f}, {z:4.2f}){why}")
    if score.matches:
        out.append("  matches (map id -> truth id: xy error, P, NEES xy):")
        for m in sorted(score.matches, key=lambda m: -m.xy_error_m):
            out.append(
                f"    {m.map_id:>3} -> {m.truth_id:>3} {m.label:<7} {m.xy_error_m:.3f} m, "
                f"P={m.existence_probability:.2f}, NEES {m.nees_xy:.2f}"
            )
    return "\n".join(out)


def format_report(scores: Sequence[MapScore]) -> str:
    return "\n\n".join([format_table(scores), *[format_details(s) for s in scores]])
