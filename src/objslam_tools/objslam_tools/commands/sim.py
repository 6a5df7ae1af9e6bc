"""``objslam sim SCENARIO --out BAG``: render a simulated bag with its ground truth."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from objslam_tools.sim.scenarios import describe_scenarios

    scenarios = "\n".join(f"  {name:8s} {text}" for name, text in describe_scenarios().items())
    parser = subparsers.add_parser(
        "sim",
        help="render a simulated bag (omnidirectional images, odometry, ground truth)",
        description="Render a rosbag2 (MCAP) bag per the data contract, with ground_truth.yaml beside it.",
        epilog=f"scenarios:\n{scenarios}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("scenario", metavar="SCENARIO", help="which scenario to render (see below)")
    parser.add_argument("--out", required=True, metavar="BAG", help="bag directory to create (must not exist)")
    parser.add_argument("--seed", type=int, default=0, help="random seed: same seed, same bag (default 0)")
    parser.add_argument(
        "--frames", type=int, default=None, help="number of images (default: the scenario's); the path stays the same"
    )
    parser.add_argument(
        "--compressed",
        action="store_true",
        help="write /camera/image_raw/compressed (sensor_msgs/CompressedImage) instead of raw rgb8 images",
    )
    parser.add_argument(
        "--format",
        dest="image_format",
        choices=("jpeg", "png"),
        default="jpeg",
        help="encoding of compressed images (default jpeg)",
    )
    parser.add_argument(
        "--camera",
        choices=("omni", "pinhole", "fisheye"),
        default="omni",
        help="omni (the bundled unified camera, level on the rotation axis, default), pinhole (640x480 "
        "plumb_bob, about 90 degrees across) or fisheye (640x640 equidistant, about 180 degrees); the last "
        "two sit 0.1 m ahead of the rotation axis, pitched 0.1 rad down, and the bag carries /tf_static",
    )
    parser.add_argument(
        "--pitch", type=float, default=None, metavar="RAD",
        help="the mount's pitch (rad, positive looks down; default: the camera's, above)",
    )  # fmt: skip
    parser.add_argument("--roll", type=float, default=None, metavar="RAD", help="the mount's roll (rad, default 0)")
    parser.add_argument(
        "--spins", type=int, default=None, metavar="N",
        help="turn once around on the spot N times along the path, so that a forward camera sees the whole "
        "room (default: 0 for omni, 3 for pinhole and fisheye)",
    )  # fmt: skip
    parser.add_argument("--jpeg-quality", type=int, default=90, help="JPEG quality 1..100 (default 90)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from objslam_common.cameras import PRESET_CAMERAS
    from objslam_tools.errors import UserError
    from objslam_tools.progress import StderrProgress
    from objslam_tools.sim.scenarios import PRESET_MOUNTS, PRESET_SPINS, build_scenario
    from objslam_tools.sim.writer import write_bag

    mount = PRESET_MOUNTS[args.camera]
    tilt = {k: v for k, v in (("pitch_rad", args.pitch), ("roll_rad", args.roll)) if v is not None}
    for name, value in tilt.items():
        if not abs(value) <= 1.2:
            raise UserError(f"--{name.split('_')[0]} must be within +-1.2 rad, got {value}")
    mount = dataclasses.replace(mount, **tilt)
    scenario = build_scenario(
        args.scenario,
        seed=args.seed,
        frames=args.frames,
        camera=PRESET_CAMERAS[args.camera],
        mount=mount,
        spins=PRESET_SPINS[args.camera] if args.spins is None else args.spins,
    )
    summary = write_bag(
        scenario,
        args.out,
        compressed=args.compressed,
        image_format=args.image_format,
        jpeg_quality=args.jpeg_quality,
        progress=StderrProgress(f"rendering {args.scenario}"),
    )
    print(
        f"wrote {summary.path}: {summary.frames} frames, {summary.odom_messages} odometry messages, "
        f"{summary.bytes_on_disk / 1e6:.1f} MB, {summary.seconds_per_frame:.3f} s per frame"
    )
    return 0
