"""A bag to a map in one process, for any association: what ``objslam map`` and ``objslam results`` run.

The detector runs once per bag (:func:`bag_inputs`); :func:`build_association_map` then
maps those inputs with the sampler (the default) or a baseline mapped by the same factor
graph: ``greedy`` (nearest neighbour, Mahalanobis gate), ``none`` (every tracklet its own
object) or ``oracle`` (the ground-truth association; simulated bags only).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

from objslam_tools.errors import UserError

if TYPE_CHECKING:  # the command line imports this module to build its parsers: the rest loads on use
    from objslam_common.catalog import Catalog
    from objslam_common.mount import CameraMountConfig
    from objslam_common.records import ImageSlices, OdometrySample
    from objslam_detector.config import DetectorConfig
    from objslam_mapper.config import MapperConfig
    from objslam_mapper.inference.chains import ChainRunner
    from objslam_mapper.map_file import BuiltMap
    from objslam_tools.bag import Bag
    from objslam_tools.ground_truth import GroundTruth
    from objslam_tools.trajectory import PoseTrack

ASSOCIATIONS = ("sampler", "greedy", "none", "oracle")


class BagInputs(NamedTuple):
    """What the mapper gets from a bag: odometry, the detector's slices per image, and what was skipped."""

    odometry: tuple[OdometrySample, ...]
    images: tuple[ImageSlices, ...]
    detection_seconds: float
    diagnostics: dict[str, Any]  # the nodes' counts of skipped messages and frames, and the mount, for the map file
    skipped: str  # the same in words ('' if nothing was skipped)
    camera_mount: CameraMountConfig  # the mount the slices were measured with, for the mapper too


class Truth(NamedTuple):
    """The ground truth of a simulated bag, for the oracle association."""

    objects: GroundTruth
    track: PoseTrack


def bag_mount(
    bag: Bag, mapper_mount: CameraMountConfig, detector_mount: CameraMountConfig
) -> tuple[CameraMountConfig, str]:
    """The camera mount to map ``bag`` with, and where it came from: the bag's /tf_static
    where it has one, else the parameters' ``camera_mount`` (the mapper's and the detector's
    are one setting: a file that gives them differently is refused rather than one ignored)."""
    from objslam_common.mount import CameraMountConfig

    default = CameraMountConfig()
    if detector_mount not in (default, mapper_mount):
        if mapper_mount != default:
            raise UserError(
                "the detector's and the mapper's parameters give different camera_mount values: give it once "
                "(as config/camera_mount.yaml does, for both)"
            )
        mapper_mount = detector_mount
    reading = bag.read_mount()
    if reading is None:
        return mapper_mount, "camera_mount parameters"
    return CameraMountConfig.of(reading.mount), reading.source


def bag_inputs(
    bag: Bag,
    detector_config: DetectorConfig,
    catalog: Catalog,
    progress: bool = True,
    *,
    mount: CameraMountConfig | None = None,
) -> BagInputs:
    """Run the detector over the bag's images and read its odometry, as the nodes would, with
    the camera mount of :func:`bag_mount` (``mount``: the mapper's ``camera_mount`` parameters)."""
    import cv2

    from objslam_common.config import to_mapping
    from objslam_detector.detector import Detector
    from objslam_mapper.ros.intake import input_diagnostics
    from objslam_tools.mapper_inputs import read_mapper_inputs
    from objslam_tools.progress import StderrProgress

    cv2.setNumThreads(1)
    started = time.monotonic()
    camera_mount, source = bag_mount(bag, mount or detector_config.camera_mount, detector_config.camera_mount)
    detector = Detector(dataclasses.replace(detector_config, camera_mount=camera_mount), catalog)
    read = read_mapper_inputs(bag, detector, StderrProgress("detecting") if progress else None)
    diagnostics = {
        **input_diagnostics(read.counters),
        "skipped_frames": dict(read.skipped_frames),
        "camera_mount": {"source": source, **to_mapping(camera_mount)},
    }
    return BagInputs(
        read.odometry, read.images, time.monotonic() - started, diagnostics, read.skipped_summary(), camera_mount
    )


def oracle_truth(bag: Bag) -> Truth:
    """Ground truth and /ground_truth/odom of a simulated bag, checked before the long work starts."""
    from objslam_tools.bag import GROUND_TRUTH_ODOM_TOPIC
    from objslam_tools.ground_truth import GROUND_TRUTH_FILE, load_ground_truth

    if not (bag.directory / GROUND_TRUTH_FILE).is_file():
        raise UserError(f"--association oracle needs the bag's ground truth: no {GROUND_TRUTH_FILE} in {bag.directory}")
    truth = load_ground_truth(bag.directory)
    if not bag.has_topic(GROUND_TRUTH_ODOM_TOPIC):
        raise UserError(f"--association oracle needs {GROUND_TRUTH_ODOM_TOPIC}, which bag {bag.path} lacks")
    return Truth(truth, bag.read_odometry(GROUND_TRUTH_ODOM_TOPIC))


def build_association_map(
    inputs: BagInputs,
    association: str,
    config: MapperConfig,
    catalog: Catalog,
    *,
    truth: Truth | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    runner: ChainRunner | None = None,
) -> BuiltMap:
    """The map of ``inputs`` under ``association`` (module docstring), with its wall time and
    association in the diagnostics; ``truth`` is needed for ``oracle``, ``runner`` runs the
    sampler's chains (default: in this process)."""
    from objslam_mapper.pipeline import build_map

    config = dataclasses.replace(config, camera_mount=inputs.camera_mount)
    started = time.monotonic()
    if association == "sampler":
        built = build_map(inputs.odometry, inputs.images, config, catalog, progress=progress, runner=runner)
    elif association == "oracle":
        from objslam_tools.oracle_map import build_oracle_map

        if truth is None:
            raise UserError("the oracle association needs the bag's ground truth")
        built = build_oracle_map(inputs.odometry, inputs.images, catalog, config, truth.objects, truth.track)
    elif association in ASSOCIATIONS:
        from objslam_mapper.inference.baselines import build_baseline_map

        built = build_baseline_map(
            inputs.odometry,
            inputs.images,
            catalog,
            association,
            graph=config.graph,
            sampler=config.sampler,
            progress=progress,
        )
    else:
        raise UserError(f"unknown association {association!r} (one of {', '.join(ASSOCIATIONS)})")
    elapsed = time.monotonic() - started + inputs.detection_seconds
    extra = {**inputs.diagnostics, "association": association, "wall_time_s": round(elapsed, 3)}
    return dataclasses.replace(built, diagnostics={**built.diagnostics, **extra})


_MINIMUM = {"samples": 1, "burn_in": 0, "seed": 0, "chains": 1}


def with_sampler_overrides(config: MapperConfig, **given: int | None) -> MapperConfig:
    """``config`` with the sampler settings a command line gave (None: keep the parameter's),
    every mistake one clear :class:`UserError` naming the flag."""
    for name, value in given.items():
        if value is not None and value < _MINIMUM[name]:
            raise UserError(f"--{name.replace('_', '-')} must be >= {_MINIMUM[name]}")
    sampler = config.sampler
    samples, burn_in = given.get("samples") or sampler.samples, given.get("burn_in")
    burn_in = sampler.burn_in if burn_in is None else burn_in
    if burn_in >= samples:
        raise UserError(
            f"the burn-in ({burn_in}) must be below the samples ({samples}): give --burn-in below --samples "
            f"(the parameters' are {sampler.burn_in} and {sampler.samples})"
        )
    try:
        sampler = dataclasses.replace(sampler, **{k: v for k, v in given.items() if v is not None})
    except ValueError as exc:
        raise UserError(f"sampler settings: {exc}") from exc
    return dataclasses.replace(config, sampler=sampler)


def convergence_line(convergence: dict) -> str:
    """One line on the chains' agreement, from a map's ``diagnostics.convergence``."""
    chains = convergence["chains"]
    if convergence["converged"] is None:
        return f"chains: {chains} (one chain: its convergence cannot be judged)"
    verdict = "yes" if convergence["converged"] else "no"
    line = (
        f"chains: {chains}, converged: {verdict} (R-hat max {convergence['rhat_max']}, "
        f"bulk ESS min {convergence['ess_bulk_min']})"
    )
    reasons = convergence.get("disagreements") or []
    return line + "".join(f"\n  {reason}" for reason in reasons)
