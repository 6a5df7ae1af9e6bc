"""The mapper's one entry point, shared by ``objslam map`` and the mapper node: inputs -> map."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from objslam_common.catalog import Catalog
from objslam_common.mount import CameraMountConfig
from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.inference.chains import ChainOutcome, ChainRunner, InProcess
from objslam_mapper.inference.diagnostics import PhaseProgress
from objslam_mapper.inference.infer import Inference, finish, prepare
from objslam_mapper.map_file import BuiltMap


def build_map(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    config: MapperConfig,
    catalog: Catalog,
    progress: PhaseProgress | None = None,
    runner: ChainRunner | None = None,
) -> BuiltMap:
    """Odometry and slices to the object-based map: the factor graph's fixed part, then
    tracklets, the chains and Algorithm 1 (:func:`~objslam_mapper.inference.infer.infer_map`);
    ``runner`` runs the chains (:func:`objslam_mapper.parallel.chain_runner`; default: here)."""
    return build_maps([(odometry, images)], config, catalog, progress, runner)[0]


def build_maps(
    runs: Sequence[tuple[Sequence[OdometrySample], Sequence[ImageSlices]]],
    config: MapperConfig,
    catalog: Catalog,
    progress: PhaseProgress | None = None,
    runner: ChainRunner | None = None,
    mounts: Sequence[CameraMountConfig] | None = None,
) -> list[BuiltMap]:
    """The maps of several runs as one job: every chain of every run handed to ``runner`` at once
    (on a cluster they all run side by side); each map is the one :func:`build_map` gives.
    ``mounts``: each run's camera mount (default: ``config.camera_mount`` for all)."""
    mounts = mounts if mounts is not None else [config.camera_mount] * len(runs)
    prepared = [
        prepare_run(odometry, images, config, catalog, mount, progress)
        for (odometry, images), mount in zip(runs, mounts, strict=True)
    ]
    return run_prepared(prepared, runner, progress)


@dataclasses.dataclass(frozen=True)
class PreparedRun:
    """One run between :func:`prepare_run` and :func:`finish_run`: its inference and input counts.
    It pickles (without a progress callback), so a run may be prepared where it was read."""

    inference: Inference
    odometry_messages: int
    slice_arrays: int


def prepare_run(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    config: MapperConfig,
    catalog: Catalog,
    mount: CameraMountConfig,
    progress: PhaseProgress | None = None,
) -> PreparedRun:
    """The factor graph's fixed part, the tracklets and the chain tasks of one run."""
    problem = build_problem(odometry, images, mount.to_mount(), catalog, config.graph)
    return PreparedRun(prepare(problem, config.sampler, progress), len(odometry), len(images))


def run_prepared(
    prepared: Sequence[PreparedRun], runner: ChainRunner | None = None, progress: PhaseProgress | None = None
) -> list[BuiltMap]:
    """Every chain of the prepared runs handed to ``runner`` at once, then each run's map."""
    for run in prepared:
        run.inference.watch.progress = progress
        run.inference.watch.resume()
    tasks = [task for run in prepared for task in run.inference.tasks]
    outcomes = (runner or InProcess()).run(tasks, prepared[0].inference.report_sampling if prepared else None)
    built = []
    for run in prepared:
        mine, outcomes = outcomes[: len(run.inference.tasks)], outcomes[len(run.inference.tasks) :]
        built.append(finish_run(run, mine))
    return built


def finish_run(run: PreparedRun, outcomes: Sequence[ChainOutcome]) -> BuiltMap:
    """Algorithm 1 over the run's chains (``outcomes`` of its tasks, in their order)."""
    one = finish(run.inference, outcomes)
    inputs = {"odometry_messages": run.odometry_messages, "slice_arrays": run.slice_arrays}
    return dataclasses.replace(one, diagnostics={**inputs, **one.diagnostics})
