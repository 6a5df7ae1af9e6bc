"""The bag simulator behind ``objslam sim``.

- ``build_scenario(name, seed, frames) -> Scenario``: scene, path, odometry (scenarios.py)
- ``render_frame(scene, map_T_base, camera, mount, rng) -> (H, W, 3) uint8`` and
  ``Renderer.render(...) -> Rendering`` (image plus which element each pixel shows) (render.py)
- ``write_bag(scenario, out, compressed=...)``: the rosbag2 bag and its ground_truth.yaml (writer.py)
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from objslam_tools.sim.render import Renderer, Rendering, render_frame
    from objslam_tools.sim.scenarios import SCENARIO_NAMES, Scenario, ScenarioError, build_scenario
    from objslam_tools.sim.scene import Appearance, Lighting, Scene
    from objslam_tools.sim.writer import write_bag

# Loaded when first asked for (PEP 562): the writer's message types and the renderer take
# half a second, and `objslam sim --help` lists the scenarios from scenarios.py alone.
_MODULE_OF = {
    "Renderer": "render",
    "Rendering": "render",
    "render_frame": "render",
    "SCENARIO_NAMES": "scenarios",
    "Scenario": "scenarios",
    "ScenarioError": "scenarios",
    "build_scenario": "scenarios",
    "Appearance": "scene",
    "Lighting": "scene",
    "Scene": "scene",
    "write_bag": "writer",
}


def __getattr__(name: str) -> Any:
    if name not in _MODULE_OF:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_MODULE_OF[name]}"), name)


__all__ = [
    "SCENARIO_NAMES",
    "Appearance",
    "Lighting",
    "Renderer",
    "Rendering",
    "Scenario",
    "ScenarioError",
    "Scene",
    "build_scenario",
    "render_frame",
    "write_bag",
]
