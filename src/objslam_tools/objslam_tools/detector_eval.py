"""Scoring the detector against a simulated bag's ground truth (``objslam eval-detector``).

For every image the ground-truth objects are projected with the ground-truth pose at the
image stamp (:mod:`objslam_tools.silhouette`). An object counts as *visible* when its
whole sector is in the image, nothing but its own table hides any of it and it is at
least ``min_width_px`` wide: recall is over visible objects. Each detection is then
explained, per class:

- by an object: Hungarian matching on bearing (sectors overlap, or bearings within a
  gate) and overlapping elevation intervals; a second detection that also fits a
  matched object is a *duplicate* (an object split into two blobs);
- else by a distractor of the same class whose projected outline it overlaps;
- else it is *unexplained*.

Errors (detection minus truth) are gathered for detections matched to visible objects:
bearing, angular width (relative), lower and upper elevation. Recall is also binned by the
visible objects' true angular width and range: the mapper's detection model
(``sampler.detection``) needs the detector's detection rate as a function of both, and
``--min-width-px 0`` shows it down to the narrowest objects.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from objslam_common.cameras import CameraModel
from objslam_common.geometry import wrap_angle
from objslam_common.mount import CameraMountConfig
from objslam_common.records import SliceMeasurement
from objslam_detector import Detector, DetectorInputError, decode_compressed, draw_slices
from objslam_tools.bag import GROUND_TRUTH_ODOM_TOPIC, ImageFrame, open_bag
from objslam_tools.errors import UserError
from objslam_tools.ground_truth import Distractor, GroundTruth, load_ground_truth
from objslam_tools.silhouette import VisibleObject, visible_objects

logger = logging.getLogger(__name__)

ERROR_NAMES = ("bearing_deg", "width_rel", "elevation_bottom_deg", "elevation_top_deg")
# Targets printed beside the figures: (what, comparison, value).
TARGETS = {
    "recall": (">=", 0.97),
    "unexplained_per_100_frames": ("<=", 1.0),
    "bearing_deg": ("<=", 0.3),
    "width_rel": ("<=", 0.10),
    "elevation_bottom_deg": ("<=", 0.5),
    "elevation_top_deg": ("<=", 0.5),
}


# Bin edges of recall by angular width (deg) and by range (m): fine where detection starts.
WIDTH_BIN_EDGES_DEG = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0, math.inf)
RANGE_BIN_EDGES_M = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, math.inf)


@dataclass
class RecallBins:
    """Visible and found objects counted in bins of one quantity (edges: lower bounds, then +inf)."""

    edges: tuple[float, ...]
    visible: list[int] = field(default_factory=list)
    found: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        bins = len(self.edges) - 1
        self.visible = self.visible or [0] * bins
        self.found = self.found or [0] * bins

    def count(self, value: float, found: bool) -> None:
        k = min(max(int(np.searchsorted(self.edges, value, side="right")) - 1, 0), len(self.visible) - 1)
        self.visible[k] += 1
        self.found[k] += int(found)

    def add(self, other: RecallBins) -> None:
        self.visible = [a + b for a, b in zip(self.visible, other.visible, strict=True)]
        self.found = [a + b for a, b in zip(self.found, other.found, strict=True)]

    def rows(self) -> list[dict[str, Any]]:
        """One row per bin with any visible object: ``[lo, hi)``, visible, found, recall."""
        return [
            {"from": lo, "to": hi, "visible": v, "found": f, "recall": f / v}
            for lo, hi, v, f in zip(self.edges, self.edges[1:], self.visible, self.found, strict=False)
            if v
        ]


@dataclass(frozen=True)
class EvalOptions:
    min_width_px: float = 6.0  # narrower objects are not expected to be detected
    max_occluded_fraction: float = 0.0  # any occlusion by other things: not counted as visible
    bearing_gate_rad: float = math.radians(1.5)  # bearing agreement accepted without sector overlap
    elevation_margin_rad: float = math.radians(1.0)  # widening of elevation intervals when matching


@dataclass
class ClassTally:
    """Counts and errors of one class (or of all)."""

    visible: int = 0
    found: int = 0  # visible objects with a matched detection
    detections: int = 0
    by_object: int = 0  # detections matched to an object (visible or not)
    duplicates: int = 0
    from_distractor: int = 0
    unexplained: int = 0
    errors: dict[str, list[float]] = field(default_factory=lambda: {name: [] for name in ERROR_NAMES})
    by_width_deg: RecallBins = field(default_factory=lambda: RecallBins(WIDTH_BIN_EDGES_DEG))
    by_range_m: RecallBins = field(default_factory=lambda: RecallBins(RANGE_BIN_EDGES_M))

    def add(self, other: ClassTally) -> None:
        for name in ("visible", "found", "detections", "by_object", "duplicates", "from_distractor", "unexplained"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        for name in ERROR_NAMES:
            self.errors[name].extend(other.errors[name])
        self.by_width_deg.add(other.by_width_deg)
        self.by_range_m.add(other.by_range_m)

    def summary(self, frames: int) -> dict[str, Any]:
        out: dict[str, Any] = {
            "visible": self.visible,
            "found": self.found,
            "recall": self.found / self.visible if self.visible else None,
            "detections": self.detections,
            "by_object": self.by_object,
            "duplicates": self.duplicates,
            "from_distractor": self.from_distractor,
            "unexplained": self.unexplained,
            "unexplained_per_100_frames": 100.0 * self.unexplained / frames if frames else None,
            "recall_by_width_deg": self.by_width_deg.rows(),
            "recall_by_range_m": self.by_range_m.rows(),
        }
        for name in ERROR_NAMES:
            values = np.asarray(self.errors[name], dtype=float)
            magnitude = np.abs(values)
            out[name] = {
                "count": int(values.size),
                "median": float(np.median(magnitude)) if values.size else None,
                "p95": float(np.percentile(magnitude, 95)) if values.size else None,
                "bias": float(np.median(values)) if values.size else None,
            }
        return out


@dataclass
class DetectorEvaluation:
    bag: str
    frames: int = 0
    skipped: dict[str, int] = field(default_factory=dict)  # reason -> frames
    seconds_detecting: float = 0.0
    tallies: dict[str, ClassTally] = field(default_factory=dict)

    def tally(self, label: str) -> ClassTally:
        return self.tallies.setdefault(label, ClassTally())

    def overall(self) -> ClassTally:
        total = ClassTally()
        for t in self.tallies.values():
            total.add(t)
        return total

    def to_dict(self) -> dict[str, Any]:
        classes = {label: t.summary(self.frames) for label, t in sorted(self.tallies.items())}
        return {
            "bag": self.bag,
            "frames": self.frames,
            "skipped_frames": dict(self.skipped),
            "ms_per_frame": 1000.0 * self.seconds_detecting / self.frames if self.frames else None,
            "classes": classes,
            "overall": self.overall().summary(self.frames),
            "targets": {k: {"comparison": c, "value": v} for k, (c, v) in TARGETS.items()},
        }


def is_visible(obj: VisibleObject, options: EvalOptions) -> bool:
    return (
        obj.in_view and obj.occluded_fraction <= options.max_occluded_fraction and obj.width_px >= options.min_width_px
    )


def _fits(sl: SliceMeasurement, obj: VisibleObject, options: EvalOptions) -> float:
    """Matching cost of a detection and an object; inf when they cannot be the same."""
    d_bearing = abs(float(wrap_angle(sl.bearing_rad - obj.bearing_rad)))
    if d_bearing > max(0.5 * (sl.angular_width_rad + obj.angular_width_rad), options.bearing_gate_rad):
        return math.inf
    m = options.elevation_margin_rad
    if sl.elevation_bottom_rad > obj.elevation_top_rad + m or sl.elevation_top_rad < obj.elevation_bottom_rad - m:
        return math.inf
    return d_bearing + abs(sl.elevation_top_rad - obj.elevation_top_rad)


def match(
    slices: Sequence[SliceMeasurement], objects: Sequence[VisibleObject], options: EvalOptions
) -> tuple[list[int | None], list[bool]]:
    """Per slice: the index of its object (or None) and whether it is a duplicate (same label assumed)."""
    cost = np.array([[_fits(s, o, options) for o in objects] for s in slices], dtype=float).reshape(
        len(slices), len(objects)
    )
    assigned: list[int | None] = [None] * len(slices)
    duplicate = [False] * len(slices)
    finite = np.isfinite(cost)
    if finite.any():
        big = 1e3 * (cost[finite].max() + 1.0)
        rows, cols = linear_sum_assignment(np.where(finite, cost, big))
        for r, c in zip(rows, cols, strict=True):
            if finite[r, c]:
                assigned[r] = int(c)
        for r in range(len(slices)):
            if assigned[r] is None and finite[r].any():
                assigned[r], duplicate[r] = int(np.argmin(cost[r])), True
    return assigned, duplicate


def distractor_sector(d: Distractor, gt: GroundTruth, map_T_base: NDArray) -> tuple[NDArray, NDArray]:
    """Azimuths and elevations (camera frame) of points spread over a distractor's face."""
    w_axis, h_axis, _n = d.axes()
    s = np.linspace(-0.5, 0.5, 7)
    sw, sh = np.meshgrid(s * d.size_m[0], s * d.size_m[1])
    points = np.asarray(d.center_m) + sw.reshape(-1, 1) * w_axis + sh.reshape(-1, 1) * h_axis
    azimuth, elevation, _range = gt.mount.direction_to(map_T_base, points)
    return azimuth, elevation


def explained_by_distractor(
    sl: SliceMeasurement, sectors: Iterable[tuple[Distractor, NDArray, NDArray]], options: EvalOptions
) -> bool:
    for d, azimuth, elevation in sectors:
        if d.label != sl.label:
            continue
        offsets = wrap_angle(azimuth - sl.bearing_rad)
        half = 0.5 * sl.angular_width_rad + options.bearing_gate_rad
        m = options.elevation_margin_rad
        if (
            offsets.min() <= half
            and offsets.max() >= -half
            and sl.elevation_bottom_rad <= elevation.max() + m
            and sl.elevation_top_rad >= elevation.min() - m
        ):
            return True
    return False


def score_frame(
    slices: Sequence[SliceMeasurement],
    objects: Sequence[VisibleObject],
    distractors: Sequence[tuple[Distractor, NDArray, NDArray]],
    evaluation: DetectorEvaluation,
    options: EvalOptions,
) -> bool:
    """Add one image's outcome to the tallies; True when something went wrong (miss, duplicate, unexplained)."""
    trouble = False
    labels = {o.label for o in objects} | {s.label for s in slices}
    for label in sorted(labels):
        tally = evaluation.tally(label)
        mine = [s for s in slices if s.label == label]
        candidates = [o for o in objects if o.label == label]
        assigned, duplicate = match(mine, candidates, options)
        found = set()
        tally.detections += len(mine)
        for sl, k, dup in zip(mine, assigned, duplicate, strict=True):
            if k is None:
                if explained_by_distractor(sl, distractors, options):
                    tally.from_distractor += 1
                else:
                    tally.unexplained += 1
                    trouble = True
                continue
            tally.by_object += 1
            if dup:
                tally.duplicates += 1
                trouble = True
                continue
            obj = candidates[k]
            if is_visible(obj, options):
                found.add(k)
                tally.errors["bearing_deg"].append(math.degrees(float(wrap_angle(sl.bearing_rad - obj.bearing_rad))))
                tally.errors["width_rel"].append(sl.angular_width_rad / obj.angular_width_rad - 1.0)
                tally.errors["elevation_bottom_deg"].append(
                    math.degrees(sl.elevation_bottom_rad - obj.elevation_bottom_rad)
                )
                tally.errors["elevation_top_deg"].append(math.degrees(sl.elevation_top_rad - obj.elevation_top_rad))
        visible = [k for k, o in enumerate(candidates) if is_visible(o, options)]
        for k in visible:
            tally.by_width_deg.count(math.degrees(candidates[k].angular_width_rad), k in found)
            tally.by_range_m.count(candidates[k].range_m, k in found)
        tally.visible += len(visible)
        tally.found += len(found)
        trouble |= len(found) < len(visible)
    return trouble


def frame_pixels(frame: ImageFrame) -> tuple[NDArray[np.uint8], str]:
    """Pixels and encoding of a bag image, raw or compressed."""
    if frame.compressed:
        return decode_compressed(frame.data, frame.encoding)
    return frame.data, frame.encoding


def evaluate_bag(
    bag_path: str | Path,
    detector: Detector,
    options: EvalOptions | None = None,
    *,
    max_frames: int | None = None,
    every: int = 1,
    progress: Callable[[int, int], None] | None = None,
    overlay_dir: Path | None = None,
    max_overlays: int = 20,
) -> DetectorEvaluation:
    """Run the detector over a simulated bag's images and score it (module docstring)."""
    options = options or EvalOptions()
    bag = open_bag(bag_path)
    gt = load_ground_truth(bag.directory)
    camera = bag.read_camera()
    # The detector measures in the level frame of the mount the bag was recorded with.
    detector = Detector(
        dataclasses.replace(detector.config, camera_mount=CameraMountConfig.of(gt.mount)), detector.catalog
    )
    view = detector.view(camera)
    track = bag.read_odometry(GROUND_TRUTH_ODOM_TOPIC) if bag.has_topic(GROUND_TRUTH_ODOM_TOPIC) else None
    if track is None:
        raise UserError(f"bag {bag_path} has no {GROUND_TRUTH_ODOM_TOPIC}: only simulated bags can be scored")
    image_topic = bag.image_topic()
    total = bag.topics[image_topic].count
    if max_frames is not None:
        total = min(total, max_frames * every)
    pano = detector.panorama(camera)
    min_elevation = pano.row_elevation(pano.rows)
    evaluation = DetectorEvaluation(bag=str(bag_path))
    overlays = 0
    for index, frame in enumerate(bag.images(image_topic)):
        if index >= total:
            break
        if progress is not None:
            progress(index + 1, total)
        if index % every:
            continue
        if not track.covers([frame.stamp_ns])[0]:
            evaluation.skipped["outside ground truth"] = evaluation.skipped.get("outside ground truth", 0) + 1
            continue
        try:
            pixels, encoding = frame_pixels(frame)
            started = time.perf_counter()
            slices = detector.detect(pixels, camera, encoding)
            evaluation.seconds_detecting += time.perf_counter() - started
        except DetectorInputError as exc:
            reason = str(exc)
            evaluation.skipped[reason] = evaluation.skipped.get(reason, 0) + 1
            continue
        evaluation.frames += 1
        pose = track.interpolate([frame.stamp_ns])[0]
        objects = visible_objects(gt, pose, view, min_elevation_rad=float(min_elevation))
        distractors = [(d, *distractor_sector(d, gt, pose)) for d in gt.distractors]
        trouble = score_frame(slices, objects, distractors, evaluation, options)
        if trouble and overlay_dir is not None and overlays < max_overlays:
            save_overlay(
                overlay_dir / f"frame_{index:05d}.png",
                pixels,
                encoding,
                slices,
                objects,
                camera=view,
                detector=detector,
            )
            overlays += 1
    if evaluation.frames == 0:
        raise UserError(f"bag {bag_path}: no image could be scored ({', '.join(evaluation.skipped) or 'no images'})")
    return evaluation


def _truth_slice(obj: VisibleObject) -> SliceMeasurement:
    """The ground truth's sector as a slice, to draw (truncated: drawn thin)."""
    bearing, width, bottom, top = obj.sector
    return SliceMeasurement(
        label=obj.label,
        confidence=1.0,
        bearing_rad=bearing,
        angular_width_rad=width,
        elevation_bottom_rad=bottom,
        elevation_top_rad=top,
        truncated=True,
    )


def save_overlay(
    path: Path,
    pixels: NDArray[np.uint8],
    encoding: str,
    slices: Sequence[SliceMeasurement],
    objects: Sequence[VisibleObject],
    *,
    camera: CameraModel,
    detector: Detector,
) -> None:
    """Detections in class colours, ground truth as thin white sectors."""
    import cv2

    truth = [_truth_slice(o) for o in objects if o.in_view]
    canvas = draw_slices(pixels, truth, camera, encoding)
    canvas = draw_slices(canvas, slices, camera, "rgb8", {c.label: c.color_rgb for c in detector.catalog})
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(canvas, cv2.COLOR_RGB2BGR))


def _fmt(value: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def format_report(evaluation: DetectorEvaluation) -> str:
    """Human-readable tables: per class and overall, with the targets beside."""
    data = evaluation.to_dict()
    lines = [
        f"bag {data['bag']}: {data['frames']} frames scored"
        + (f", {sum(data['skipped_frames'].values())} skipped" if data["skipped_frames"] else "")
        + (f", detector {data['ms_per_frame']:.1f} ms/frame" if data["ms_per_frame"] is not None else "")
    ]
    for reason, count in data["skipped_frames"].items():
        lines.append(f"  skipped {count}: {reason}")
    header = (
        f"{'class':8s} {'visible':>7s} {'recall':>6s} {'slices':>6s} {'object':>6s} {'dupl':>5s} {'distr':>5s} "
        f"{'unexpl':>6s}  {'bearing deg':>17s}  {'width %':>17s}  {'elev bottom deg':>17s}  {'elev top deg':>17s}"
    )
    lines += [
        "",
        header,
        f"{'':8s} {'':>7s} {'':>6s} {'':>6s} {'':>6s} {'':>5s} {'':>5s} {'':>6s}" + "  median/p95/bias" * 4,
    ]
    rows = [*data["classes"].items(), ("all", data["overall"])]
    for label, s in rows:
        errors = []
        for name in ERROR_NAMES:
            e = s[name]
            scale = 100.0 if name == "width_rel" else 1.0
            errors.append(f"{_fmt(e['median'], scale)}/{_fmt(e['p95'], scale)}/{_fmt(e['bias'], scale)}".rjust(17))
        lines.append(
            f"{label:8s} {s['visible']:7d} {_fmt(s['recall'], digits=3):>6s} {s['detections']:6d} {s['by_object']:6d} "
            f"{s['duplicates']:5d} {s['from_distractor']:5d} {s['unexplained']:6d}  " + "  ".join(errors)
        )
    overall = data["overall"]
    for title, key, unit in (("width", "recall_by_width_deg", "deg"), ("range", "recall_by_range_m", "m")):
        lines += ["", f"recall by true {title} ({unit}), all classes:"]
        lines += [
            f"  {row['from']:5g} - {row['to']:<5g} visible {row['visible']:6d}  found {row['found']:6d}  "
            f"recall {row['recall']:.3f}"
            for row in overall[key]
        ]
    lines += ["", "targets (overall):"]
    for name, (comparison, target) in TARGETS.items():
        value = overall[name]["median"] if isinstance(overall[name], dict) else overall[name]
        if value is None:
            verdict, shown = "n/a", "-"
        else:
            ok = value >= target if comparison == ">=" else value <= target
            verdict, shown = ("ok" if ok else "MISSED"), f"{value:.3f}"
        what = f"median {name}" if isinstance(overall[name], dict) else name
        lines.append(f"  {what:32s} {shown:>8s}  target {comparison} {target:<5g} {verdict}")
    return "\n".join(lines)
