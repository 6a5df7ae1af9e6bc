"""``objslam map BAG --out map.yaml``: the whole pipeline in one process."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ASSOCIATIONS = ("sampler", "greedy", "none", "oracle")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "map",
        help="build the object map of a bag in one process (detector, sampler, map building)",
        description=(
            "Run the detector over the bag's images, read /odom, sample the data association with "
            "Metropolis-Hastings and build the object-based map (paper Algorithm 1). Deterministic for a seed."
        ),
    )
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory (MCAP or sqlite3)")
    parser.add_argument("--out", required=True, metavar="MAP", help="map YAML to write")
    parser.add_argument("--samples", type=int, default=None, help="MCMC samples incl. burn-in (default 6000)")
    parser.add_argument("--burn-in", type=int, default=None, help="samples discarded first (default 2500)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (default from the parameters)")
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")
    parser.add_argument("--detector-params", metavar="FILE", default=None, help="detector parameters")
    parser.add_argument("--figures", metavar="DIR", default=None, help="also write the pictures here")
    parser.add_argument(
        "--association",
        choices=ASSOCIATIONS,
        default="sampler",
        help=(
            "data association: sampler (MCMC, default); baselines mapped by the same factor graph: "
            "greedy (nearest neighbour, Mahalanobis gate), none (every tracklet its own object), "
            "oracle (ground truth; simulated bags only)"
        ),
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    import cv2

    from objslam_common.catalog import load_catalog
    from objslam_common.config import default_config_dir, load_config
    from objslam_detector.config import DetectorConfig
    from objslam_detector.detector import Detector
    from objslam_mapper.config import MapperConfig
    from objslam_mapper.map_file import write_map
    from objslam_mapper.pipeline import build_map
    from objslam_tools.bag import open_bag
    from objslam_tools.errors import UserError
    from objslam_tools.mapper_inputs import detect_bag, odometry_samples
    from objslam_tools.progress import StderrProgress

    for name in ("samples", "burn_in", "seed"):
        value = getattr(args, name)
        if value is not None and value < (1 if name == "samples" else 0):
            raise UserError(f"--{name.replace('_', '-')} must be {'>= 1' if name == 'samples' else '>= 0'}")
    out = Path(args.out)
    if out.is_dir():
        raise UserError(f"--out {out} is a directory; give the map file's path")
    bag = open_bag(args.bag)
    params = args.params or default_config_dir() / "mapper.yaml"
    config = load_config(MapperConfig, params, "mapper")
    overrides = {
        k: v for k, v in (("samples", args.samples), ("burn_in", args.burn_in), ("seed", args.seed)) if v is not None
    }
    config = dataclasses.replace(config, sampler=dataclasses.replace(config.sampler, **overrides))
    if config.sampler.burn_in >= config.sampler.samples:
        raise UserError(f"--burn-in ({config.sampler.burn_in}) must be below --samples ({config.sampler.samples})")
    catalog = load_catalog(config.catalog_file or None)
    oracle_truth = _oracle_truth(bag) if args.association == "oracle" else None
    cv2.setNumThreads(1)
    detector = Detector(load_config(DetectorConfig, args.detector_params, "detector"), catalog)

    started = time.monotonic()
    odometry = odometry_samples(bag)
    images = detect_bag(bag, detector, StderrProgress("detecting"))
    sampling = StderrProgress("sampling", unit="samples")

    def progress(phase: str, done: int, total: int) -> None:
        if phase == "sampling":
            sampling(done, total)

    if args.association == "sampler":
        built = build_map(odometry, images, config, catalog, progress=progress)
    elif args.association == "oracle":
        from objslam_tools.oracle_map import build_oracle_map

        built = build_oracle_map(odometry, images, catalog, config, *oracle_truth)
    else:
        from objslam_mapper.inference.baselines import build_baseline_map

        associating = StderrProgress("associating", unit="tracklets")
        built = build_baseline_map(
            odometry,
            images,
            catalog,
            args.association,
            graph=config.graph,
            sampler=config.sampler,
            progress=lambda phase, done, total: associating(done, total) if phase == "association" else None,
        )
    elapsed = time.monotonic() - started
    built = dataclasses.replace(
        built, diagnostics={**built.diagnostics, "association": args.association, "wall_time_s": round(elapsed, 3)}
    )
    write_map(out, built)
    print(
        f"map ({args.association}): {len(built.objects)} objects ({len(built.rejected)} rejected) "
        f"from {len(images)} images and {len(odometry)} odometry messages in {elapsed:.1f} s -> {out}"
    )
    for obj in built.objects:
        x, y, z = obj.position_m
        print(
            f"  #{obj.id:<3} {obj.label:<7} x {x:7.2f}  y {y:7.2f}  z {z:5.2f}  d {obj.size_m[0]:.2f}  "
            f"h {obj.size_m[1]:.2f}  P {obj.existence_probability:.2f}  n {obj.measurement_count}"
        )
    if args.figures:
        from objslam_tools.figures import write_figures

        paths = write_figures(built, Path(args.figures), bag=bag, catalog=catalog, mount=config.camera_mount.to_mount())
        print(f"figures: {', '.join(str(p) for p in paths)}")
    sys.stdout.flush()
    return 0


def _oracle_truth(bag):
    """Ground truth and /ground_truth/odom of a simulated bag, checked before the long work starts."""
    from objslam_tools.bag import GROUND_TRUTH_ODOM_TOPIC
    from objslam_tools.errors import UserError
    from objslam_tools.ground_truth import GROUND_TRUTH_FILE, load_ground_truth

    if not (bag.directory / GROUND_TRUTH_FILE).is_file():
        raise UserError(f"--association oracle needs the bag's ground truth: no {GROUND_TRUTH_FILE} in {bag.directory}")
    truth = load_ground_truth(bag.directory)
    if not bag.has_topic(GROUND_TRUTH_ODOM_TOPIC):
        raise UserError(f"--association oracle needs {GROUND_TRUTH_ODOM_TOPIC}, which bag {bag.path} lacks")
    return truth, bag.read_odometry(GROUND_TRUTH_ODOM_TOPIC)
