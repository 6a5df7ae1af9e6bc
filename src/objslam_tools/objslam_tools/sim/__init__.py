"""The bag simulator behind ``objslam sim``.

- ``build_scenario(name, seed, frames) -> Scenario``: scene, path, odometry (scenarios.py)
- ``render_frame(scene, map_T_base, camera, mount, rng) -> (H, W, 3) uint8`` and
  ``Renderer.render(...) -> Rendering`` (image plus which element each pixel shows) (render.py)
- ``write_bag(scenario, out, compressed=...)``: the rosbag2 bag and its ground_truth.yaml (writer.py)
"""

from objslam_tools.sim.render import Renderer, Rendering, render_frame
from objslam_tools.sim.scenarios import SCENARIO_NAMES, Scenario, ScenarioError, build_scenario
from objslam_tools.sim.scene import Appearance, Lighting, Scene
from objslam_tools.sim.writer import write_bag

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
