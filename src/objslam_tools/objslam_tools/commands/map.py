"""``objslam map BAG --out map.yaml``: the whole pipeline in one process."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from objslam_tools.mapping import ASSOCIATIONS


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
    parser.add_argument(
        "--chains", type=int, default=None, help="Metropolis-Hastings chains from dispersed starts (default 4)"
    )
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        default=None,
        help="run the chains on this Ray cluster (default: parallel.ray_address, RAY_ADDRESS, else a local Ray)",
    )
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")
    parser.add_argument("--detector-params", metavar="FILE", default=None, help="detector parameters")
    parser.add_argument("--figures", metavar="DIR", default=None, help="also write the pictures here")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
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
    from objslam_common.catalog import load_catalog
    from objslam_common.config import default_config_dir, load_config
    from objslam_detector.config import DetectorConfig
    from objslam_mapper.config import MapperConfig
    from objslam_mapper.map_file import write_map
    from objslam_mapper.parallel import RayRunner, running_chains
    from objslam_tools.bag import open_bag
    from objslam_tools.mapping import (
        bag_inputs,
        build_association_map,
        convergence_line,
        oracle_truth,
        with_sampler_overrides,
    )
    from objslam_tools.outputs import check_output_dir, check_output_file
    from objslam_tools.progress import StderrProgress

    bag = open_bag(args.bag)
    params = args.params or default_config_dir() / "mapper.yaml"
    inputs_given = [bag.path, Path(params), *([Path(args.detector_params)] if args.detector_params else [])]
    out = check_output_file(Path(args.out), inputs_given, force=args.force)
    if args.figures:
        check_output_dir(Path(args.figures), inputs_given, flag="--figures")
    config = load_config(MapperConfig, params, "mapper")
    config = with_sampler_overrides(
        config, samples=args.samples, burn_in=args.burn_in, seed=args.seed, chains=args.chains
    )
    catalog = load_catalog(config.catalog_file or None)
    truth = oracle_truth(bag) if args.association == "oracle" else None

    detector_config = load_config(DetectorConfig, args.detector_params, "detector")
    sampling = StderrProgress("sampling", unit="samples")
    associating = StderrProgress("associating", unit="tracklets")

    def progress(phase: str, done: int, total: int) -> None:
        if phase == "sampling":
            sampling(done, total)
        elif phase == "association":
            associating(done, total)

    with running_chains(config.parallel, config.sampler.chains, args.ray) as runner:
        if args.association == "sampler" and isinstance(runner, RayRunner) and runner.address:
            runner.ray()  # a wrong address or token fails now, not after minutes of detection
        inputs = bag_inputs(bag, detector_config, catalog, mount=config.camera_mount)
        built = build_association_map(
            inputs, args.association, config, catalog, truth=truth, progress=progress, runner=runner
        )
    write_map(out, built)
    elapsed = built.diagnostics["wall_time_s"]
    print(
        f"map ({args.association}): {len(built.objects)} objects ({len(built.rejected)} rejected) "
        f"from {len(inputs.images)} images and {len(inputs.odometry)} odometry messages in {elapsed:.1f} s -> {out}"
    )
    if inputs.skipped:
        print(
            f"objslam map: left out {inputs.skipped} (as the nodes would; counted in the map's diagnostics)",
            file=sys.stderr,
        )
    convergence = built.diagnostics.get("convergence")
    if convergence:
        print(convergence_line(convergence))
    for obj in built.objects:
        x, y, z = obj.position_m
        by_chain = " ".join(f"{p:.2f}" for p in obj.existence_by_chain) if len(obj.existence_by_chain) > 1 else ""
        print(
            f"  #{obj.id:<3} {obj.label:<7} x {x:7.2f}  y {y:7.2f}  z {z:5.2f}  d {obj.size_m[0]:.2f}  "
            f"h {obj.size_m[1]:.2f}  P {obj.existence_probability:.2f}"
            + (f" [{by_chain}]" if by_chain else "")
            + f"  n {obj.measurement_count}"
        )
    if args.figures:
        from objslam_tools.figures import write_figures

        paths = write_figures(built, Path(args.figures), bag=bag, catalog=catalog, mount=inputs.camera_mount.to_mount())
        print(f"figures: {', '.join(str(p) for p in paths)}")
    sys.stdout.flush()
    return 0
