"""The mapper's one entry point, shared by ``objslam map`` and the mapper node: inputs -> map."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from objslam_common.catalog import Catalog
from objslam_common.mount import CameraMountConfig
from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.inference.chains import ChainRunner, InProcess
from objslam_mapper.inference.diagnostics import PhaseProgress
from objslam_mapper.inference.infer import finish, prepare
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
        prepare(
            build_problem(odometry, images, mount.to_mount(), catalog, config.graph),
            config.sampler,
            progress,
        )
        for (odometry, images), mount in zip(runs, mounts, strict=True)
    ]
    tasks = [task for inference in prepared for task in inference.tasks]
    outcomes = (runner or InProcess()).run(tasks, prepared[0].report_sampling if prepared else None)
    built = []
    for (odometry, images), inference in zip(runs, prepared, strict=True):
        mine, outcomes = outcomes[: len(inference.tasks)], outcomes[len(inference.tasks) :]
        one = finish(inference, mine)
        inputs = {"odometry_messages": len(odometry), "slice_arrays": len(images)}
        built.append(dataclasses.replace(one, diagnostics={**inputs, **one.diagnostics}))
    return built
