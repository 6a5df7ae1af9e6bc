"""``objslam map-batch BAG... --out DIR``: many bags mapped as one job, bags and chains as tasks."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "map-batch",
        help="map many bags as one job: detection and chains as Ray tasks, one table at the end",
        description=(
            "Map each BAG as `objslam map` would (the same map for the same settings), as one job: the "
            "detector and the tracklets run on every bag as a task, then every chain of every bag as a task, "
            "on a local Ray (every core) or the cluster of --ray. Writes DIR/<bag name>.yaml per bag and "
            "prints one table: bag, objects, converged, time."
        ),
    )
    parser.add_argument("bags", nargs="+", metavar="BAG", help="rosbag2 directories (MCAP or sqlite3)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="folder for the map files")
    parser.add_argument("--chains", type=int, default=None, help="chains per bag (default from the parameters)")
    parser.add_argument("--force", action="store_true", help="replace map files already in DIR")
    parser.add_argument("--seed", type=int, default=None, help="random seed (default from the parameters)")
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")
    parser.add_argument("--detector-params", metavar="FILE", default=None, help="detector parameters")
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        default=None,
        help="the Ray cluster (default: parallel.ray_address, RAY_ADDRESS, local)",
    )
    parser.set_defaults(func=run)


def _detect_and_prepare(path: str, detector_config: Any, catalog: Any, config: Any) -> tuple[Any, Any]:
    """One bag's inputs, and its run prepared for the chains (tracklets and chain tasks): a Ray
    task, so the bags' preparations run side by side, not one after another here."""
    from objslam_mapper.pipeline import prepare_run
    from objslam_tools.bag import open_bag
    from objslam_tools.mapping import bag_inputs

    read = bag_inputs(open_bag(path), detector_config, catalog, progress=False, mount=config.camera_mount)
    return read, prepare_run(read.odometry, read.images, config, catalog, read.camera_mount)


def biggest_first(bags: Sequence[Any]) -> list[int]:
    """The order the bags' preparations are handed to Ray, which starts tasks in the order they
    come: the biggest bag's preparation is the longest and its chains (the longest) wait for
    it, while the small bags' preparations fit beside it. Ties keep the command line's order."""
    return sorted(range(len(bags)), key=lambda i: -bags[i].message_count)


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import time

    from objslam_common.catalog import load_catalog
    from objslam_common.config import default_config_dir, load_config
    from objslam_detector.config import DetectorConfig
    from objslam_mapper.config import MapperConfig
    from objslam_mapper.map_file import write_map
    from objslam_mapper.parallel import RayRunner, running_chains
    from objslam_mapper.pipeline import run_prepared
    from objslam_tools.bag import open_bag
    from objslam_tools.errors import UserError
    from objslam_tools.mapping import with_sampler_overrides
    from objslam_tools.outputs import check_output_dir, check_output_file
    from objslam_tools.progress import StderrProgress

    started = time.monotonic()
    bags = [open_bag(b) for b in args.bags]  # every bag checked before any work
    names = [b.directory.name for b in bags]
    if len(set(names)) != len(names):
        raise UserError("two bags have the same folder name; their maps would overwrite each other")
    params = Path(args.params or default_config_dir() / "mapper.yaml")
    inputs_given = [*(b.path for b in bags), params, *([Path(args.detector_params)] if args.detector_params else [])]
    check_output_dir(args.out, inputs_given, flag="--out")
    for name in names:
        check_output_file(args.out / f"{name}.yaml", inputs_given, force=args.force)
    config = with_sampler_overrides(load_config(MapperConfig, params, "mapper"), chains=args.chains, seed=args.seed)
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create --out {args.out}: {exc.strerror or exc}") from exc
    catalog = load_catalog(config.catalog_file or None)
    detector_config = load_config(DetectorConfig, args.detector_params, "detector")

    # Many bags are parallel work even with one chain each: a Ray runner whatever the chain count.
    with running_chains(config.parallel, max(2, config.sampler.chains), args.ray) as runner:
        if isinstance(runner, RayRunner):
            ray = runner.ray()
            detect = ray.remote(num_cpus=1)(_detect_and_prepare)
            pending = {
                i: detect.remote(str(bags[i].path), detector_config, catalog, config) for i in biggest_first(bags)
            }
            ready = ray.get([pending[i] for i in range(len(bags))])
        else:
            ready = [_detect_and_prepare(str(b.path), detector_config, catalog, config) for b in bags]
        inputs = [read for read, _ in ready]
        detected = time.monotonic()
        sampling = StderrProgress("sampling", unit="steps")
        maps = run_prepared(
            [prepared for _, prepared in ready],
            runner,
            progress=lambda phase, done, total: sampling(done, total) if phase == "sampling" else None,
        )
    elapsed = time.monotonic() - started
    print(f"{'bag':24s} {'objects':>7s} {'rejected':>8s}  {'converged':9s} {'R-hat max':>9s} {'chains s':>9s}")
    for name, built, read in zip(names, maps, inputs, strict=True):
        built = dataclasses.replace(
            built, diagnostics={**built.diagnostics, **read.diagnostics, "association": "sampler"}
        )
        if read.skipped:
            print(f"objslam map-batch: {name}: left out {read.skipped}", file=sys.stderr)
        path = write_map(args.out / f"{name}.yaml", built)
        convergence = built.diagnostics.get("convergence") or {}
        verdict = {True: "yes", False: "no", None: "-"}[convergence.get("converged")]
        print(
            f"{name:24s} {len(built.objects):7d} {len(built.rejected):8d}  {verdict:9s} "
            f"{convergence.get('rhat_max', '-')!s:>9s} {built.diagnostics['timings_s'].get('chains', 0.0):9.1f}"
            f"   -> {path}"
        )
    print(f"{len(maps)} bags in {elapsed:.1f} s wall (detection and tracklets {detected - started:.1f} s)")
    print("chains s: the seconds of a bag's chains, summed (they ran side by side with the others')")
    return 0
