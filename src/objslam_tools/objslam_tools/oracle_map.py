"""The oracle baseline: the map of the ground-truth data association of a simulated bag.

Each slice is given the real object that explains it by :func:`objslam_tools.oracle.oracle_assignment`
(ground-truth poses and objects; slices no real object explains are distractors or noise).
To change only the association, the oracle sees the same measurements as the sampler and
the other baselines: those chained into tracklets (isolated detections are dropped before
any association). Those measurements are grouped by their real object; slices of no object,
and slices the model cannot explain from their object at the truth (merged blobs:
:func:`objslam_tools.oracle.truth_residual_chi2`), are left out (clutter), and the map is
one known-association solve with marginals
(:func:`objslam_mapper.inference.baselines.map_of_groups`). It lives here, not in the core, because
the core never reads ground truth. :func:`oracle_problem` gives the diagnostics in
``objslam diagnose`` a simulated bag's problem and its ground-truth association in one call.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from objslam_common.catalog import Catalog
from objslam_common.config import load_config
from objslam_common.records import ImageSlices, OdometrySample
from objslam_detector.config import DetectorConfig
from objslam_detector.detector import Detector
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.problem import GraphProblem, build_problem
from objslam_mapper.inference.baselines import map_of_groups
from objslam_mapper.inference.tracklets import tracklets_of_problem
from objslam_mapper.map_file import BuiltMap
from objslam_tools.bag import open_bag
from objslam_tools.evaluate import Reference, load_reference
from objslam_tools.ground_truth import GroundTruth
from objslam_tools.mapper_inputs import read_mapper_inputs
from objslam_tools.oracle import OracleOptions, oracle_assignment, truth_residual_chi2
from objslam_tools.trajectory import PoseTrack

logger = logging.getLogger(__name__)


def oracle_groups(
    problem: GraphProblem,
    images: Sequence[ImageSlices],
    ground_truth: GroundTruth,
    ground_truth_track: PoseTrack,
    measurements: Sequence[int] | None = None,
    options: OracleOptions | None = None,
) -> tuple[dict[int, list[int]], int]:
    """Real object id -> the problem's measurement indices it explains (of ``measurements``, default all).

    Also returns how many slices the oracle gave an object but the measurement model rejects
    (residual at the truth beyond ``options.residual_gate_chi2``); they are in no group.
    """
    options = options or OracleOptions()
    ids = oracle_assignment(images, ground_truth, ground_truth_track, options)
    keep = range(problem.measurement_count) if measurements is None else sorted(set(measurements))
    assigned: list[tuple[int, int]] = []
    for m in keep:
        object_id = ids[int(problem.measurement_image[m])][int(problem.measurement_slot[m])]
        if object_id is not None:
            assigned.append((int(m), object_id))
    if not assigned:
        return {}, 0
    index = np.array([m for m, _ in assigned], dtype=np.int64)
    objects = {o.id: o for o in ground_truth.objects}
    truth = [objects[object_id] for _, object_id in assigned]
    # Images outside /ground_truth/odom got no object above, so every pose here is covered.
    poses = ground_truth_track.interpolate(problem.stamps_ns[problem.measurement_pose[index]])
    chi2 = truth_residual_chi2(
        problem.measurements[index],
        problem.measurement_stddev[index],
        poses,
        [o.position_m for o in truth],
        [o.size_m for o in truth],
        ground_truth.mount,
        bounds=problem.measurement_bounds[index],
    )
    consistent = chi2 <= options.residual_gate_chi2
    groups: dict[int, list[int]] = {}
    for (m, object_id), ok in zip(assigned, consistent, strict=True):
        if ok:
            groups.setdefault(object_id, []).append(m)
    inconsistent = int(np.count_nonzero(~consistent))
    if inconsistent:
        logger.info(
            "oracle: %d of %d slices of real objects are beyond the model's chi-square gate (merged blobs): clutter",
            inconsistent,
            len(assigned),
        )
    return groups, inconsistent


class OracleAssociation(NamedTuple):
    """A problem's ground-truth association: real object id -> its measurements, and what was left out."""

    groups: dict[int, list[int]]
    tracklet_count: int
    isolated_dropped: int
    in_tracklets: int  # measurements chained into tracklets
    inconsistent: int  # of those, given an object but beyond the model's gate at the truth


def oracle_association(
    problem: GraphProblem,
    images: Sequence[ImageSlices],
    config: MapperConfig,
    ground_truth: GroundTruth,
    ground_truth_track: PoseTrack,
) -> OracleAssociation:
    """The measurements the sampler would see (chained into tracklets), grouped by their real object."""
    chained = tracklets_of_problem(problem, config.sampler.tracklets)
    in_tracklets = [m for t in chained.tracklets for m in t.measurement_indices]
    groups, inconsistent = oracle_groups(problem, images, ground_truth, ground_truth_track, in_tracklets)
    return OracleAssociation(
        groups, len(chained.tracklets), len(chained.dropped_measurements), len(in_tracklets), inconsistent
    )


class OracleProblem(NamedTuple):
    """A simulated bag's factor-graph problem and its ground-truth association, for diagnostics."""

    problem: GraphProblem
    reference: Reference
    truth_ids: list[int]  # real object of each group
    groups: list[list[int]]  # measurement indices per real object, in truth_ids order


def oracle_problem(bag_path: str, config: MapperConfig, catalog: Catalog) -> OracleProblem:
    """Detect a simulated bag with the default detector and associate its slices by the ground truth."""
    bag = open_bag(bag_path)
    reference = load_reference(bag_path)
    detector = Detector(load_config(DetectorConfig, None, "detector"), catalog)
    odometry, images, _, _ = read_mapper_inputs(bag, detector)
    graph = config.graph
    problem = build_problem(odometry, images, graph.camera_mount.to_mount(), catalog, graph)
    by_truth = oracle_association(problem, images, config, reference.ground_truth, reference.ground_truth_track).groups
    truth_ids = sorted(by_truth)
    return OracleProblem(problem, reference, truth_ids, [by_truth[i] for i in truth_ids])


def build_oracle_map(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    catalog: Catalog,
    config: MapperConfig,
    ground_truth: GroundTruth,
    ground_truth_track: PoseTrack,
) -> BuiltMap:
    """Odometry and slices to the map of the ground-truth association (module docstring)."""
    started = time.perf_counter()
    graph = config.graph
    problem = build_problem(odometry, images, graph.camera_mount.to_mount(), catalog, graph)
    oracle = oracle_association(problem, images, config, ground_truth, ground_truth_track)
    groups = oracle.groups
    diagnostics = {
        "association": "oracle",
        "poses": problem.pose_count,
        "measurements": problem.measurement_count,
        "tracklets": oracle.tracklet_count,
        "isolated_dropped": oracle.isolated_dropped,
        "association_objects": len(groups),
        "clutter_measurements": oracle.in_tracklets - sum(len(g) for g in groups.values()),
        "inconsistent_measurements": oracle.inconsistent,
    }
    built = map_of_groups(problem, [groups[k] for k in sorted(groups)], config.sampler, diagnostics)
    built.diagnostics["timings_s"] = {"total": round(time.perf_counter() - started, 3)}
    return built
