"""``objslam bench mapper [BAG]``: how fast the map is built from a bag's detections, against the naive way.

The map build timed is everything after the detector: factor-graph problem, tracklets,
the MH chain (proposals, screens, graph solves, clutter solves), marginals and Algorithm 1.
The detector runs first and is timed on its own line (``objslam bench detector`` measures it).

The naive baseline is one fresh GTSAM Levenberg-Marquardt solve per MH step,
with one CustomFactor per detection (:func:`objslam_tools.bench._naive.time_naive_solves`):
a few such solves are timed on the chain's start association and proposals from it, and
extrapolated to the whole chain.

Scaling: the office scene rendered at 1x, 2x and 4x its frames (same path, more images),
each built with the main run's samples and burn-in (or ``--scaling-samples``); the growth
exponent is the slope of log(time) against log(frames). Shorter chains weigh the start
(cold solves of the start state, which grow faster than the frames) more than a real map
build does.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pickle
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

DESCRIPTION = "map build time (MH sampling, solves, marginals) on a bag, against the naive GTSAM way, and its scaling"
TARGET_WALL_S = 60.0
TARGET_SPEEDUP = 20.0
OFFICE_FRAMES = 400
PHASES = (
    ("problem", "factor-graph problem"),
    ("tracklets", "tracklets"),
    ("proposals_and_chain", "proposals and chain bookkeeping"),
    ("screening", "screens (conditional object solves)"),
    ("solving_during_sampling", "graph solves"),
    ("clutter_solves", "clutter solves (once per tracklet)"),
    ("marginals", "marginals (kept states)"),
    ("map_building", "Algorithm 1 bookkeeping"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", nargs="?", default="bags/office", metavar="BAG", help="bag (default bags/office)")
    parser.add_argument("--samples", type=int, default=6000, help="MH samples incl. burn-in (default 6000)")
    parser.add_argument("--burn-in", type=int, default=2500, help="burn-in samples (default 2500)")
    parser.add_argument("--seed", type=int, default=None, help="chain seed (default from the parameters)")
    parser.add_argument(
        "--chains",
        type=int,
        default=1,
        help="chains, one after another in this process (default 1: the cost of a chain; "
        "objslam bench chains times several in parallel)",
    )
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")
    parser.add_argument(
        "--naive-seconds", type=float, default=30.0, help="time budget of the naive GTSAM baseline (default 30 s)"
    )
    parser.add_argument(
        "--scaling",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also time the office scene at 1x, 2x, 4x frames (renders missing bags into --cache-dir)",
    )
    parser.add_argument(
        "--scaling-samples",
        type=int,
        default=None,
        help="samples per scale, a quarter of them burn-in (default: --samples and --burn-in, the real workload)",
    )
    parser.add_argument(
        "--cache-dir", default="out/bench", help="rendered scaling bags and detections (default out/bench)"
    )
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON")


def _config(args: argparse.Namespace, samples: int, burn_in: int) -> Any:
    from objslam_common.config import default_config_dir, load_config
    from objslam_mapper.config import MapperConfig

    config = load_config(MapperConfig, args.params or default_config_dir() / "mapper.yaml", "mapper")
    overrides: dict[str, int] = {"samples": samples, "burn_in": burn_in, "chains": args.chains}
    if args.seed is not None:
        overrides["seed"] = args.seed
    return dataclasses.replace(config, sampler=dataclasses.replace(config.sampler, **overrides))


def detector_fingerprint(detector_config: Any, catalog: Any) -> str:
    """What the detections of a bag depend on besides the bag: the detector's code, settings and catalog."""
    import hashlib

    import objslam_detector

    digest = hashlib.sha256(repr((detector_config, catalog)).encode())
    for source in sorted(Path(objslam_detector.__file__).resolve().parent.glob("*.py")):
        digest.update(source.read_bytes())
    return digest.hexdigest()


def _detections(bag_path: Path, config: Any, cache_dir: Path | None) -> tuple[tuple, tuple, float]:
    """(odometry, images, detector seconds); detections are cached per bag in ``cache_dir`` (0 s when reused).

    A cached entry is used only for the same bag files and the same detector (code, settings, catalog).
    """
    from objslam_common.catalog import load_catalog
    from objslam_common.config import load_config
    from objslam_detector.config import DetectorConfig
    from objslam_detector.detector import Detector
    from objslam_tools.bag import open_bag
    from objslam_tools.mapper_inputs import read_mapper_inputs

    bag = open_bag(str(bag_path))
    catalog = load_catalog(config.catalog_file or None)
    detector_config = load_config(DetectorConfig, None, "detector")
    stamp = (max(p.stat().st_mtime_ns for p in bag_path.iterdir()), detector_fingerprint(detector_config, catalog))
    cache = None
    if cache_dir is not None:
        cache = cache_dir / f"{bag_path.resolve().name}.detections.pkl"
        if cache.exists():
            saved_stamp, odometry, images = pickle.loads(cache.read_bytes())
            if saved_stamp == stamp:
                return odometry, images, 0.0
    detector = Detector(detector_config, catalog)
    started = time.perf_counter()
    odometry, images, _, _ = read_mapper_inputs(bag, detector)
    seconds = time.perf_counter() - started
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        cache.write_bytes(pickle.dumps((stamp, odometry, images)))
    return odometry, images, seconds


def _build(odometry: tuple, images: tuple, config: Any) -> dict[str, Any]:
    """Time one map build (problem included, detector excluded)."""
    from objslam_common.catalog import load_catalog
    from objslam_mapper.graph.problem import build_problem
    from objslam_mapper.inference.infer import infer_map

    catalog = load_catalog(config.catalog_file or None)
    wall, cpu = time.perf_counter(), time.process_time()
    problem = build_problem(odometry, images, config.graph.camera_mount.to_mount(), catalog, config.graph)
    problem_seconds = time.perf_counter() - wall
    built = infer_map(problem, config.sampler)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    phases = dict(built.diagnostics["timings_s"])
    phases["problem"] = round(problem_seconds, 3)
    return {"problem": problem, "built": built, "wall_s": wall, "cpu_s": cpu, "phases": phases}


def _naive(problem: Any, config: Any, max_seconds: float) -> dict[str, Any]:
    """Seconds per naive GTSAM solve on the start association and proposals from it."""
    import numpy as np

    from objslam_mapper.inference.chain import MetropolisHastings
    from objslam_mapper.inference.chains import sight_lines
    from objslam_mapper.inference.start import initial_association
    from objslam_mapper.inference.target import AssociationTarget, TargetOptions
    from objslam_mapper.inference.tracklets import tracklets_of_problem
    from objslam_tools.bench._naive import time_naive_solves

    sampler_cfg = config.sampler
    chained = tracklets_of_problem(problem, sampler_cfg.tracklets)
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=sampler_cfg.clutter))
    sampler = MetropolisHastings(
        chained.labels,
        lambda _state: 0.0,
        sampler_cfg.moves,
        positions_xy_m=[t.position_xy_m for t in chained.tracklets],
        tracklet_weights=[len(t) for t in chained.tracklets],
        allow_clutter=sampler_cfg.clutter.enabled,
        sight_lines=sight_lines(chained),
    )
    start = initial_association(chained.tracklets, sampler_cfg.initial_merge_distance_m)
    rng = np.random.default_rng(0)
    states = [start]
    view = sampler.proposals.view(start)
    while len(states) < 20:
        proposal = sampler.proposals.propose(view, rng)
        if proposal is None:
            break
        if proposal.view.state.n_objects:
            states.append(proposal.view.state)
    seconds, count = time_naive_solves(problem, [target.groups(s) for s in states], max_seconds)
    return {"seconds_per_solve": seconds, "solves_timed": count}


def _scale_bag(cache_dir: Path, factor: int, base_bag: Path) -> Path:
    """The office scene at ``factor`` times its frames: the bundled bag at 1x, else rendered once."""
    if factor == 1 and (base_bag / "metadata.yaml").exists():
        return base_bag
    path = cache_dir / f"office_{factor}x"
    if not (path / "metadata.yaml").exists():
        print(f"rendering {path} ({factor * OFFICE_FRAMES} frames, may take minutes)...", file=sys.stderr, flush=True)
        cmd = [sys.executable, "-m", "objslam_tools.cli", "sim", "office", "--seed", "1", "--compressed"]
        cmd += ["--frames", str(factor * OFFICE_FRAMES), "--out", str(path)]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return path


def scaling_chain(args: argparse.Namespace) -> tuple[int, int]:
    """Samples and burn-in of each scaling run: the main run's, unless --scaling-samples says otherwise."""
    if args.scaling_samples is None:
        return args.samples, args.burn_in
    return args.scaling_samples, min(args.scaling_samples // 4, args.scaling_samples - 1)


def _scaling(args: argparse.Namespace, cache_dir: Path) -> dict[str, Any]:
    import numpy as np

    from objslam_common.config import default_config_dir

    rows = []
    samples, burn_in = scaling_chain(args)
    config = _config(args, samples, burn_in)
    for factor in (1, 2, 4):
        bag = _scale_bag(cache_dir, factor, default_config_dir().parent / "bags" / "office")
        odometry, images, _ = _detections(bag, config, cache_dir)
        run = _build(odometry, images, config)
        rows.append(
            {
                "factor": factor,
                "frames": len(images),
                "measurements": run["problem"].measurement_count,
                "tracklets": run["built"].diagnostics["tracklets"],
                "wall_s": run["wall_s"],
                "cpu_s": run["cpu_s"],
                "objects": len(run["built"].objects),
                "graph_solves": run["built"].diagnostics["solves"],
                "seconds_per_graph_solve": run["phases"]["solving_during_sampling"]
                / max(run["built"].diagnostics["solves"], 1),
            }
        )
    frames = np.log([r["frames"] for r in rows])

    def exponent(key: str) -> float:
        return float(np.polyfit(frames, np.log([r[key] for r in rows]), 1)[0])

    return {
        "samples": samples,
        "rows": rows,
        "growth_exponent_wall": exponent("wall_s"),
        "growth_exponent_cpu": exponent("cpu_s"),
        # The wall time is (number of graph solves) x (time per solve) + the rest: the
        # chain decides the first (it solves the proposals its screen lets through), the
        # solver the second.
        "growth_exponent_graph_solves": exponent("graph_solves"),
        "growth_exponent_per_graph_solve": exponent("seconds_per_graph_solve"),
    }


def run(args: argparse.Namespace) -> int:
    from objslam_tools.errors import UserError

    if args.samples < 1 or not 0 <= args.burn_in < args.samples:
        raise UserError("need --samples >= 1 and 0 <= --burn-in < --samples")
    if args.chains < 1:
        raise UserError("--chains must be at least 1")
    if args.scaling_samples is not None and args.scaling_samples < 2:
        raise UserError("--scaling-samples must be at least 2")
    bag = Path(args.bag)
    if not (bag / "metadata.yaml").exists():
        raise UserError(f"{bag} is not a rosbag2 directory (no metadata.yaml)")
    cache_dir = Path(args.cache_dir)
    config = _config(args, args.samples, args.burn_in)
    odometry, images, detector_s = _detections(bag, config, None)
    main = _build(odometry, images, config)
    built, diag = main["built"], main["built"].diagnostics
    naive = _naive(main["problem"], config, args.naive_seconds) if args.naive_seconds > 0 else None
    result: dict[str, Any] = {
        "target": "mapper",
        "bag": str(bag),
        "frames": len(images),
        "measurements": main["problem"].measurement_count,
        "tracklets": diag["tracklets"],
        "samples": args.samples,
        "burn_in": args.burn_in,
        "detector_s": detector_s,
        "wall_s": main["wall_s"],
        "cpu_s": main["cpu_s"],
        "samples_per_s": args.samples / main["wall_s"],
        "phases_s": {key: main["phases"].get(key, 0.0) for key, _ in PHASES},
        "graph_solves": diag.get("solves"),
        "screens": diag.get("screens"),
        "object_solves": diag.get("object_solves"),
        "clutter_solves": diag.get("clutter_solves"),
        "marginal_solves": diag.get("marginal_solves"),
        "distinct_associations_visited": sum(c["distinct_associations_visited"] for c in diag.get("chain_runs", [])),
        "acceptance_rate": diag.get("acceptance_rate"),
        "objects": len(built.objects),
        "rejected": len(built.rejected),
        "target_wall_s": TARGET_WALL_S,
        "target_speedup": TARGET_SPEEDUP,
    }
    if naive is not None:
        naive_total = naive["seconds_per_solve"] * args.samples
        solves = result["graph_solves"] or 0
        ours_per_solve = main["phases"]["solving_during_sampling"] / solves if solves else float("nan")
        naive.update(
            {
                "extrapolated_chain_s": naive_total,
                "speedup": naive_total / main["wall_s"],
                "our_seconds_per_graph_solve": ours_per_solve,
                "speedup_per_solve": naive["seconds_per_solve"] / ours_per_solve,
            }
        )
        result["naive"] = naive
    if args.scaling:
        result["scaling"] = _scaling(args, cache_dir)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(_table(result))
    return 0


def _table(r: dict[str, Any]) -> str:
    def ok(good: bool) -> str:
        return "ok" if good else "MISSED"

    lines = [
        f"mapper bench: {r['bag']} ({r['frames']} frames, {r['measurements']} slices, {r['tracklets']} tracklets), "
        f"{r['samples']} samples ({r['burn_in']} burn-in)",
        f"  {'detector (not in the map build)':<40} {r['detector_s']:9.2f} s",
        f"  {'map build wall time':<40} {r['wall_s']:9.2f} s   target <= {r['target_wall_s']:g} s: "
        f"{ok(r['wall_s'] <= r['target_wall_s'])}",
        f"  {'map build CPU time':<40} {r['cpu_s']:9.2f} s",
        f"  {'samples per second':<40} {r['samples_per_s']:9.1f}",
        "  time per phase (wall):",
    ]
    for key, name in PHASES:
        lines.append(f"    {name:<38} {r['phases_s'][key]:9.2f} s")
    lines += [
        f"  {'graph solves / screens / object solves':<40} {r['graph_solves']} / {r['screens']} / {r['object_solves']}",
        f"  {'clutter solves / marginal solves':<40} {r['clutter_solves']} / {r['marginal_solves']}",
        f"  {'distinct associations visited':<40} {r['distinct_associations_visited']}",
        f"  {'acceptance rate':<40} {r['acceptance_rate']}",
        f"  {'map':<40} {r['objects']} objects, {r['rejected']} rejected",
    ]
    naive = r.get("naive")
    if naive is not None:
        lines += [
            f"  {'naive GTSAM solve (1 CustomFactor/slice)':<40} {naive['seconds_per_solve']:9.2f} s per solve "
            f"({naive['solves_timed']} timed)",
            f"  {'naive chain (one solve per sample)':<40} {naive['extrapolated_chain_s']:9.0f} s (extrapolated)",
            f"  {'speedup over naive':<40} {naive['speedup']:9.0f} x   target >= {r['target_speedup']:g} x: "
            f"{ok(naive['speedup'] >= r['target_speedup'])}",
            f"  {'one graph solve: naive / ours':<40} {naive['seconds_per_solve']:9.2f} s / "
            f"{naive['our_seconds_per_graph_solve']:.3f} s = {naive['speedup_per_solve']:.0f} x",
        ]
    scaling = r.get("scaling")
    if scaling is not None:
        lines.append(f"  scaling with bag length ({scaling['samples']} samples each):")
        lines.append(
            f"    {'scale':<6} {'frames':>7} {'slices':>8} {'tracklets':>10} {'wall s':>8} {'CPU s':>8} "
            f"{'solves':>7} {'s/solve':>8} objects"
        )
        for row in scaling["rows"]:
            lines.append(
                f"    {str(row['factor']) + 'x':<6} {row['frames']:>7} {row['measurements']:>8} {row['tracklets']:>10} "
                f"{row['wall_s']:>8.2f} {row['cpu_s']:>8.2f} {row['graph_solves']:>7} "
                f"{row['seconds_per_graph_solve']:>8.3f} {row['objects']:>7}"
            )
        exponent = scaling["growth_exponent_wall"]
        lines.append(
            f"    growth exponent (time ~ frames^k): k = {exponent:.2f} wall, "
            f"{scaling['growth_exponent_cpu']:.2f} CPU   target <= 1 (linear, +0.1 for noise): {ok(exponent <= 1.1)}"
        )
        lines.append(
            f"    ... of which graph solves ~ frames^{scaling['growth_exponent_graph_solves']:.2f}, "
            f"time per graph solve ~ frames^{scaling['growth_exponent_per_graph_solve']:.2f}"
        )
    return "\n".join(lines)
