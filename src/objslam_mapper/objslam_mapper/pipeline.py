"""The mapper's whole configuration and its one entry point, shared by ``objslam map`` and the node.

``MapperConfig`` mirrors the ``mapper: ros__parameters:`` section of ``config/mapper.yaml``
key for key: the factor graph's sections (``camera_mount``, ``odometry``, ``slice_noise``,
``solver``), the association sampler's (``sampler``), the class catalog, and the node's
own settings (``ros``, ignored by ``objslam map``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

from objslam_common.catalog import Catalog
from objslam_common.config import setting
from objslam_common.mount import CameraMountConfig
from objslam_common.records import ImageSlices, OdometrySample

from objslam_mapper.config import GraphConfig, OdometryNoiseConfig, SliceNoiseConfig, SolverConfig
from objslam_mapper.inference.infer import PhaseProgress, SamplerConfig
from objslam_mapper.inference.infer import build_map as _infer
from objslam_mapper.map_file import BuiltMap


@dataclass(frozen=True)
class RosConfig:
    """The mapper node's topics, buffers and outputs (not used by ``objslam map``)."""

    odom_topic: str = setting("/odom", "wheel odometry (nav_msgs/Odometry, odom -> base_link)")
    slices_topic: str = setting("/objslam/slices", "detector output (objslam_msgs/SliceArray)")
    max_buffered_odometry: int = setting(200_000, "odometry messages kept; the oldest go first", minimum=1)
    max_buffered_images: int = setting(50_000, "slice arrays kept; the oldest go first", minimum=1)
    subscription_depth: int = setting(1000, "subscription queue depth (reliable): room for bursts", minimum=1)
    output_dir: str = setting("", "if set, write map.yaml here after each build")
    write_figures: bool = setting(False, "with output_dir: also write the top view and overlays (needs objslam_tools)")


@dataclass(frozen=True)
class MapperConfig:
    catalog_file: str = setting("", "class catalog file; empty = the bundled config/catalog.yaml")
    camera_mount: CameraMountConfig = setting(CameraMountConfig(), "camera mount on the robot")
    odometry: OdometryNoiseConfig = setting(OdometryNoiseConfig(), "odometry factor noise")
    slice_noise: SliceNoiseConfig = setting(SliceNoiseConfig(), "slice measurement noise")
    solver: SolverConfig = setting(SolverConfig(), "known-association solver")
    sampler: SamplerConfig = setting(SamplerConfig(), "association sampler and map building")
    ros: RosConfig = setting(RosConfig(), "mapper node topics, buffers and outputs")

    @property
    def graph(self) -> GraphConfig:
        return GraphConfig(
            camera_mount=self.camera_mount, odometry=self.odometry, slice_noise=self.slice_noise, solver=self.solver
        )


def build_map(
    odometry: Sequence[OdometrySample],
    images: Sequence[ImageSlices],
    config: MapperConfig,
    catalog: Catalog,
    progress: PhaseProgress | None = None,
) -> BuiltMap:
    """Odometry and slices to the object-based map (tracklets, MH over associations, Algorithm 1)."""
    built = _infer(odometry, images, catalog, graph=config.graph, sampler=config.sampler, progress=progress)
    inputs = {"odometry_messages": len(odometry), "slice_arrays": len(images)}
    return dataclasses.replace(built, diagnostics={**inputs, **built.diagnostics})
