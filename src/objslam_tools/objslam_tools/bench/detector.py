"""``objslam bench detector``: images per second of the detector on 640x640 frames, one core."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from numpy.typing import NDArray

DESCRIPTION = "detector throughput (images/s) on 640x640 omnidirectional frames, one core"
TARGET_IMAGES_PER_S = 30.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=300, metavar="N", help="images to detect in (default 300)")
    parser.add_argument(
        "--distinct", type=int, default=20, metavar="K", help="distinct frames rendered and cycled through (default 20)"
    )
    parser.add_argument("--bag", default=None, help="take the frames from this bag instead of rendering them")
    parser.add_argument("--params", metavar="FILE", default=None, help="detector parameter file (ROS 2 params YAML)")
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON")


def _rendered_frames(count: int) -> tuple[list[tuple[NDArray[np.uint8], str]], object, str]:
    from objslam_tools.sim import build_scenario, render_frame

    scenario = build_scenario("office")
    picks = np.linspace(0, scenario.frames - 1, count).astype(int)
    rng = np.random.default_rng(0)
    frames = [
        (render_frame(scenario.scene, scenario.image_poses[i], scenario.camera, scenario.mount, rng), "rgb8")
        for i in picks
    ]
    return frames, scenario.camera, f"office scenario, {count} distinct frames"


def _bag_frames(path: str, count: int) -> tuple[list[tuple[NDArray[np.uint8], str]], object, str]:
    from objslam_tools.bag import open_bag
    from objslam_tools.detector_eval import frame_pixels

    bag = open_bag(path)
    camera = bag.read_camera()
    frames = []
    for frame in bag.images():
        frames.append(frame_pixels(frame))
        if len(frames) >= count:
            break
    return frames, camera, f"{len(frames)} frames of {path}"


def run(args: argparse.Namespace) -> int:
    from objslam_common.config import load_config
    from objslam_detector import Detector, DetectorConfig
    from objslam_tools.bench import use_one_core
    from objslam_tools.errors import UserError

    if args.frames < 1 or args.distinct < 1:
        raise UserError("--frames and --distinct must be at least 1")
    cpu = use_one_core()
    detector = Detector(load_config(DetectorConfig, args.params, "detector"))
    frames, camera, source = _bag_frames(args.bag, args.distinct) if args.bag else _rendered_frames(args.distinct)
    if not frames:
        raise UserError(f"no images in {args.bag}")
    detector.detect(*frames[0][:1], camera, frames[0][1])  # builds the remap tables: not part of the rate
    durations = np.empty(args.frames)
    slices = 0
    for i in range(args.frames):
        pixels, encoding = frames[i % len(frames)]
        started = time.perf_counter()
        slices += len(detector.detect(pixels, camera, encoding))
        durations[i] = time.perf_counter() - started
    rate = args.frames / durations.sum()
    result = {
        "target": "detector",
        "source": source,
        "image_size": [camera.width_px, camera.height_px],
        "cpu": cpu,
        "images": args.frames,
        "images_per_s": rate,
        "ms_per_image_mean": 1000.0 * float(durations.mean()),
        "ms_per_image_p95": 1000.0 * float(np.percentile(durations, 95)),
        "slices_per_image": slices / args.frames,
        "target_images_per_s": TARGET_IMAGES_PER_S,
        "meets_target": bool(rate >= TARGET_IMAGES_PER_S),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        verdict = "ok" if result["meets_target"] else "MISSED"
        print(
            f"detector, {camera.width_px}x{camera.height_px} px ({source}), 1 core (cpu {cpu}): "
            f"{args.frames} images in {durations.sum():.2f} s\n"
            f"  {rate:.1f} images/s ({result['ms_per_image_mean']:.1f} ms mean, "
            f"{result['ms_per_image_p95']:.1f} ms p95 per image), {result['slices_per_image']:.1f} slices/image\n"
            f"  target >= {TARGET_IMAGES_PER_S:g} images/s: {verdict}"
        )
    return 0
