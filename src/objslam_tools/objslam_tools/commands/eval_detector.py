"""``objslam eval-detector BAG``: score the detector against a simulated bag's ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "eval-detector",
        help="score the detector on a simulated bag (recall, spurious slices, angle errors)",
        description=(
            "Run the detector over a simulated bag's images (raw or compressed) and compare its slices with the "
            "ground-truth objects projected from /ground_truth/odom: recall of visible objects, slices explained by "
            "distractors or by nothing, and bearing / width / elevation errors per class."
        ),
    )
    parser.add_argument("bag", metavar="BAG", help="simulated bag directory (with ground_truth.yaml)")
    parser.add_argument("--params", metavar="FILE", default=None, help="detector parameter file (ROS 2 params YAML)")
    parser.add_argument("--frames", type=int, default=None, metavar="N", help="score at most N images")
    parser.add_argument("--every", type=int, default=1, metavar="K", help="score every K-th image (default 1)")
    parser.add_argument(
        "--min-width-px", type=float, default=6.0, metavar="PX", help="narrowest object counted as visible (default 6)"
    )
    parser.add_argument(
        "--overlays",
        metavar="DIR",
        default=None,
        help="write up to 20 images of frames with a miss, a duplicate or an unexplained slice "
        "(detections in class colours, ground truth in white)",
    )
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON instead of tables")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import cv2

    from objslam_common.config import load_config
    from objslam_detector import Detector, DetectorConfig
    from objslam_tools.detector_eval import EvalOptions, evaluate_bag, format_report
    from objslam_tools.errors import UserError
    from objslam_tools.progress import StderrProgress

    if args.frames is not None and args.frames < 1:
        raise UserError(f"--frames must be at least 1, got {args.frames}")
    if args.every < 1:
        raise UserError(f"--every must be at least 1, got {args.every}")
    cv2.setNumThreads(1)
    detector = Detector(load_config(DetectorConfig, args.params, "detector"))
    evaluation = evaluate_bag(
        args.bag,
        detector,
        EvalOptions(min_width_px=args.min_width_px),
        max_frames=args.frames,
        every=args.every,
        progress=StderrProgress(f"detecting in {args.bag}"),
        overlay_dir=Path(args.overlays) if args.overlays else None,
    )
    print(json.dumps(evaluation.to_dict(), indent=2) if args.json else format_report(evaluation))
    return 0
