"""objslam_tools.figures: the PNGs exist, are real pictures, and overlays land on the objects."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from matplotlib.image import imread
from matplotlib.path import Path as MplPath

from objslam_mapper.map_file import MappedObject
from objslam_tools.bag import open_bag
from objslam_tools.errors import UserError
from objslam_tools.figures import _sector_outline, write_figures
from objslam_tools.ground_truth import GroundTruthObject
from tests.objslam_tools import synthetic_scene as scene


@pytest.fixture(scope="module")
def bag_dir(tmp_path_factory):
    return scene.write_scene_bag(tmp_path_factory.mktemp("fig") / "bag", images_every=10)


def _map_with_rejected():
    rejected = MappedObject(
        40, "yellow", scene.to_odom((0.3, 2.0, 0.0)), (0.5, 0.3), 0.2, ((0.05, 0.01, 0), (0.01, 0.09, 0), (0, 0, 1e-3))
    )
    return replace(scene.perfect_map(), rejected=(rejected,))


def _assert_real_picture(path):
    assert path.is_file() and path.stat().st_size > 5_000
    pixels = imread(path)
    assert pixels.ndim == 3 and pixels.shape[0] > 300 and pixels.shape[1] > 300
    # Not one flat colour: many distinct colours and real variation.
    flat = pixels[:, :, :3].reshape(-1, 3)
    packed = np.round(flat * 255).astype(np.int64) @ np.array([65536, 256, 1])
    assert len(np.unique(packed)) > 20
    assert flat.std() > 0.05


def test_top_down_without_bag(tmp_path):
    paths = write_figures(_map_with_rejected(), tmp_path / "out")
    assert [p.name for p in paths] == ["map_top_down.png"]
    _assert_real_picture(paths[0])


def test_with_bag_ground_truth_and_overlays(bag_dir, tmp_path):
    paths = write_figures(_map_with_rejected(), tmp_path, bag=bag_dir, prefix="run")
    names = [p.name for p in paths]
    assert names[0] == "run_top_down.png"
    assert len(names) == 4 and all(n.startswith("run_overlay_") for n in names[1:])
    for p in paths:
        _assert_real_picture(p)


def test_chosen_frames(bag_dir, tmp_path):
    paths = write_figures(scene.perfect_map(), tmp_path, bag=bag_dir, frames=[0, -1])
    assert [p.name for p in paths[1:]] == ["map_overlay_0000.png", "map_overlay_0005.png"]
    with pytest.raises(UserError, match="out of range"):
        write_figures(scene.perfect_map(), tmp_path, bag=bag_dir, frames=[6])


def test_overlay_outline_encloses_the_rendered_object(bag_dir):
    """The sector the overlay draws covers the pixels the (ground-truth) renderer painted."""
    from objslam_common.mount import CameraMount
    from objslam_mapper.model.slice_model import predict_slices

    frame = next(open_bag(bag_dir).images())
    stamps, poses = scene.ground_truth_poses()
    pose = poses[list(stamps).index(frame.stamp_ns)]
    green: GroundTruthObject = scene.OBJECTS[2]
    pred = predict_slices(pose, green.position_m, green.size_m, CameraMount(), jacobians=False)
    poly = _sector_outline(scene.CAMERA, *pred.values[0])
    painted = np.argwhere(np.all(frame.data == (30, 160, 60), axis=2))  # (row, col)
    assert len(painted) > 10
    uv = painted[:, ::-1].astype(float)
    inside = MplPath(poly).contains_points(uv)
    # Pixels on the rim may fall just outside the sampled outline: allow one pixel.
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("pkd,kd->pk", uv[:, None, :] - a[None], ab) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    nearest = a[None] + t[:, :, None] * ab[None]
    near_rim = np.min(np.linalg.norm(uv[:, None, :] - nearest, axis=2), axis=1) <= 1.0
    assert np.all(inside | near_rim)
    assert inside.mean() > 0.5


def test_the_chains_figure_traces_each_chain(tmp_path):
    runs = [
        {
            "chain": k,
            "start": start,
            "trace": {
                "every_steps": 20,
                "log_target": list(900.0 + 100 * np.tanh(np.arange(50) / (5 + 10 * k))),
                "objects": [12 - min(k + i // 10, 8) for i in range(50)],
            },
        }
        for k, start in enumerate(("heuristic", "singletons", "greedy"))
    ]
    diagnostics = {"chain_runs": runs, "burn_in": 400, "convergence": {"converged": False, "rhat_max": 1.3}}
    paths = write_figures(replace(scene.perfect_map(), diagnostics=diagnostics), tmp_path, prefix="run")
    assert [p.name for p in paths] == ["run_top_down.png", "run_chains.png"]
    _assert_real_picture(paths[1])
    assert write_figures(scene.perfect_map(), tmp_path / "one")[-1].name == "map_top_down.png"  # no traces: none
