"""The mapper's one entry point, shared by ``objslam map`` and the mapper node: inputs -> map."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from objslam_common.catalog import Catalog
from objslam_common.records import ImageSlices, OdometrySample
from objslam_mapper.config import MapperConfig
from objslam_mapper.graph.problem import build_problem
from objslam_mapper.inference.diagnostics import PhaseProgress
from objslam_mapper.inference.infer import infer_map
from objslam_mapper.map_file import BuiltMap


def build_map(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    config: MapperConfig,
    catalog: Catalog,
    progress: PhaseProgress | None = None,
) -> BuiltMap:
    """Odometry and slices to the object-based map: the factor graph's fixed part, then
    tracklets, MH over associations and Algorithm 1 (:func:`~objslam_mapper.inference.infer.infer_map`)."""
    problem = build_problem(odometry, images, config.camera_mount.to_mount(), catalog, config.graph)
    built = infer_map(problem, config.sampler, progress)
    inputs = {"odometry_messages": len(odometry), "slice_arrays": len(images)}
    return dataclasses.replace(built, diagnostics={**inputs, **built.diagnostics})
