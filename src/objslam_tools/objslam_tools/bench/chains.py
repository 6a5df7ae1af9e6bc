"""``objslam bench chains [BAG]``: what several chains cost in wall time, and many bags as one job.

Chains: the map of a bag (default ``bags/office``) is built from its cached detections with
1, 2 and 4 chains (``--chains``): one chain in this process, several as Ray tasks on a local
Ray of ``--workers`` CPUs, started once before the first build and kept up across the builds
(as the mapper node keeps it; ``objslam map`` pays the start, printed on its own line, once
per command). Each count is built ``--repeats`` times, the counts taking turns, and the
median is reported: this machine's timings wander by tens of percent between sessions,
so only ratios within one run mean anything. Per count: wall time of the build (detector
excluded), its ratio to one chain's, the chains' own seconds summed (their CPU: a chain is
single-threaded), the speedup (chains per wall second against one chain's), and whether
the chains converged. Target: 2 chains on 2 cores take at most 1.2x one chain's wall time.

That ratio has three parts, which ``--alone`` (on by default) tells apart: the same chains
are also run one after another in this process, so each is timed alone. The slowest one's
seconds over the one chain's seconds (chain against chain) are the work its start adds (a
chain from singletons walks to the mode through states no other chain solves); the
sampling phase's wall time over the slowest chain alone is what running in parallel costs
(Ray, two processes on two cores); the rest is the build outside the chains (tracklets,
pooling, diagnostics, the map), which is printed for each count.

Batch (``--batch``): the five scenarios (rendered into ``--bags-dir`` when not bundled) mapped
by ``objslam map`` one after another in one process each (``parallel.backend: inprocess``:
detector, then the chains one by one), against ``objslam map-batch`` of all five as one
job on a local Ray of ``--workers`` CPUs (detectors and chains as tasks), both as commands
with the same chains and samples; their maps are compared too. Target: the batch at least
1.7x faster on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

DESCRIPTION = "wall time of 1, 2 and 4 chains on a bag (Ray), and of map-batch against one map after another"
TARGET_TWO_CHAINS_RATIO = 1.2
TARGET_BATCH_SPEEDUP = 1.7
SCENARIOS = ("small", "office", "twins", "clutter", "loop")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", nargs="?", default="bags/office", metavar="BAG", help="bag (default bags/office)")
    parser.add_argument("--chains", default="1,2,4", help="chain counts to time, comma-separated (default 1,2,4)")
    parser.add_argument("--samples", type=int, default=6000, help="MH samples per chain incl. burn-in (default 6000)")
    parser.add_argument("--burn-in", type=int, default=2500, help="burn-in samples (default 2500)")
    parser.add_argument("--repeats", type=int, default=1, help="builds per chain count; the median is shown")
    parser.add_argument("--workers", type=int, default=2, help="CPUs of the local Ray (default 2)")
    parser.add_argument(
        "--alone",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run each count's chains one after another in this process, timing each chain alone",
    )
    parser.add_argument(
        "--batch",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also time map-batch of the five scenarios against mapping them one after another",
    )
    parser.add_argument("--batch-chains", type=int, default=2, help="chains per bag in the batch part (default 2)")
    parser.add_argument("--batch-samples", type=int, default=3000, help="samples per chain in the batch part")
    parser.add_argument("--batch-burn-in", type=int, default=1000, help="burn-in in the batch part")
    parser.add_argument("--cache-dir", default="out/bench", help="cached detections (default out/bench)")
    parser.add_argument(
        "--bags-dir", default="out/bags", help="rendered scenarios, shared with objslam results (default out/bags)"
    )
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON")


def _chain_counts(text: str) -> list[int]:
    from objslam_tools.errors import UserError

    try:
        counts = [int(part) for part in text.split(",") if part.strip()]
    except ValueError as exc:
        raise UserError(f"--chains wants counts like 1,2,4, got {text!r}") from exc
    if not counts or min(counts) < 1:
        raise UserError(f"--chains wants counts of at least 1, got {text!r}")
    return counts


def _time_builds(args: argparse.Namespace, counts: list[int]) -> dict[str, Any]:
    """Median wall time of the builds per chain count (module docstring)."""
    import dataclasses

    from objslam_common.catalog import load_catalog
    from objslam_mapper.inference.chains import InProcess
    from objslam_mapper.parallel import RayRunner
    from objslam_mapper.pipeline import build_map
    from objslam_tools.bench.mapper import _config, _detections

    args.seed, args.params = None, None
    config = _config(args, args.samples, args.burn_in)
    odometry, images, _ = _detections(Path(args.bag), config, Path(args.cache_dir))
    catalog = load_catalog(config.catalog_file or None)
    ray = RayRunner(None, args.workers)
    started = time.perf_counter()
    if max(counts) > 1:
        ray.ray()
    ray_start_s = time.perf_counter() - started
    runs: dict[int, list[dict[str, Any]]] = {k: [] for k in counts}

    def build(k: int, runner: Any) -> tuple[float, Any]:
        sampler = dataclasses.replace(config.sampler, chains=k)
        wall = time.perf_counter()
        built = build_map(odometry, images, dataclasses.replace(config, sampler=sampler), catalog, None, runner)
        return time.perf_counter() - wall, built

    try:
        for repeat in range(args.repeats):
            for k in counts:
                print(f"chains {k}, run {repeat + 1}/{args.repeats}...", file=sys.stderr, flush=True)
                wall, built = build(k, InProcess() if k == 1 else ray)
                convergence = built.diagnostics.get("convergence") or {}
                run = {
                    "wall_s": wall,
                    "chain_s": built.diagnostics["timings_s"]["chains"],
                    "sampling_s": built.diagnostics["timings_s"]["sampling"],
                    "converged": convergence.get("converged"),
                    "rhat_max": convergence.get("rhat_max"),
                    "objects": len(built.objects),
                }
                if args.alone and k > 1:
                    print(f"chains {k} one after another, run {repeat + 1}/{args.repeats}...", file=sys.stderr)
                    _, alone = build(k, InProcess())
                    run["alone_s"] = alone.diagnostics["timings_s"]["chain_seconds"]
                runs[k].append(run)
    finally:
        ray.close()
    rows = [_row(k, runs[k]) for k in counts]
    one_row = next((r for r in rows if r["chains"] == 1), None)
    one = one_row["wall_s"] if one_row else None
    one_chain = one_row["chain_s"] if one_row else None
    for row in rows:
        row["ratio_to_one"] = row["wall_s"] / one if one else None
        row["speedup"] = row["chains"] * one / row["wall_s"] if one else None
        slowest = row.get("slowest_alone_s")
        # Chain seconds against chain seconds, and the sampling phase against the slowest
        # chain alone: the wall times hold the build's work outside the chains as well.
        row["slowest_alone_to_one"] = slowest / one_chain if one_chain and slowest else None
        row["sampling_to_slowest_alone"] = row["sampling_s"] / slowest if slowest else None
    return {"bag": args.bag, "frames": len(images), "ray_start_s": ray_start_s, "rows": rows}


def _row(k: int, runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One chain count's medians over its runs."""
    row: dict[str, Any] = {
        "chains": k,
        "wall_s": statistics.median(r["wall_s"] for r in runs),
        "wall_s_all": [round(r["wall_s"], 2) for r in runs],
        "chain_s": statistics.median(r["chain_s"] for r in runs),
        "sampling_s": statistics.median(r["sampling_s"] for r in runs),
        # The build outside its chains: tracklets, start of the pool, diagnostics, the map.
        "outside_s": statistics.median(r["wall_s"] - r["sampling_s"] for r in runs),
        "converged": [r["converged"] for r in runs],
        "rhat_max": [r["rhat_max"] for r in runs],
        "objects": [r["objects"] for r in runs],
    }
    alone = [r["alone_s"] for r in runs if "alone_s" in r]
    if alone:
        # Per chain the median over the runs: a chain does the same work in every run.
        row["alone_s"] = [round(statistics.median(column), 2) for column in zip(*alone, strict=True)]
        row["slowest_alone_s"] = max(row["alone_s"])
    return row


def _batch(args: argparse.Namespace) -> dict[str, Any]:
    """``objslam map`` one bag after another (in-process) against ``objslam map-batch`` (Ray)."""
    import yaml

    from objslam_common.config import default_config_dir
    from objslam_tools.results import Scenario, scenario_bag

    repo = default_config_dir().parent
    bags = [scenario_bag(Scenario.parse(name), repo, Path(args.bags_dir)) for name in SCENARIOS]
    sampler = {"chains": args.batch_chains, "samples": args.batch_samples, "burn_in": args.batch_burn_in}
    with tempfile.TemporaryDirectory(prefix="objslam-bench-") as tmp:
        folder = Path(tmp)
        inprocess = folder / "inprocess.yaml"
        inprocess.write_text(
            yaml.safe_dump({"mapper": {"ros__parameters": {"sampler": sampler, "parallel": {"backend": "inprocess"}}}})
        )
        on_ray = folder / "ray.yaml"
        on_ray.write_text(
            yaml.safe_dump({"mapper": {"ros__parameters": {"sampler": sampler, "parallel": {"workers": args.workers}}}})
        )
        one_by_one = folder / "one_by_one"
        started = time.perf_counter()
        for bag in bags:
            print(f"objslam map {bag.name} (in this process)...", file=sys.stderr, flush=True)
            _command("map", str(bag), "--out", str(one_by_one / f"{bag.name}.yaml"), "--params", str(inprocess))
        sequential_s = time.perf_counter() - started
        print("objslam map-batch of all of them...", file=sys.stderr, flush=True)
        started = time.perf_counter()
        _command("map-batch", *map(str, bags), "--out", str(folder / "batch"), "--params", str(on_ray))
        batch_s = time.perf_counter() - started
        same = [_same_map(one_by_one / f"{b.name}.yaml", folder / "batch" / f"{b.name}.yaml") for b in bags]
    return {
        "bags": [b.name for b in bags],
        **sampler,
        "workers": args.workers,
        "one_after_another_s": sequential_s,
        "map_batch_s": batch_s,
        "speedup": sequential_s / batch_s,
        "same_maps": same,
    }


def _command(*args: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "objslam_tools.cli", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    if done.returncode != 0:
        from objslam_tools.errors import ToolsError

        raise ToolsError(f"objslam {args[0]} failed: {done.stderr.strip().splitlines()[-1:]}")


def _same_map(a: Path, b: Path) -> bool:
    import yaml

    def content(path: Path) -> Any:
        data = yaml.safe_load(path.read_text())
        data["diagnostics"] = {k: v for k, v in data["diagnostics"].items() if k not in ("timings_s", "wall_time_s")}
        return data

    return bool(content(a) == content(b))


def run(args: argparse.Namespace) -> int:
    from objslam_tools.errors import UserError

    counts = _chain_counts(args.chains)
    if args.samples < 1 or not 0 <= args.burn_in < args.samples:
        raise UserError("need --samples >= 1 and 0 <= --burn-in < --samples")
    if args.batch_samples < 1 or not 0 <= args.batch_burn_in < args.batch_samples or args.batch_chains < 1:
        raise UserError("need --batch-chains >= 1, --batch-samples >= 1 and 0 <= --batch-burn-in < --batch-samples")
    if args.repeats < 1 or args.workers < 1:
        raise UserError("--repeats and --workers must be at least 1")
    if not (Path(args.bag) / "metadata.yaml").exists():
        raise UserError(f"{args.bag} is not a rosbag2 directory (no metadata.yaml)")
    result: dict[str, Any] = {
        "target": "chains",
        "samples": args.samples,
        "burn_in": args.burn_in,
        "workers": args.workers,
        "repeats": args.repeats,
        "chains": _time_builds(args, counts),
        "target_two_chains_ratio": TARGET_TWO_CHAINS_RATIO,
        "target_batch_speedup": TARGET_BATCH_SPEEDUP,
    }
    if args.batch:
        result["batch"] = _batch(args)
    print(json.dumps(result, indent=2) if args.json else format_table(result))
    return 0


def format_table(r: dict[str, Any]) -> str:
    def ok(good: bool) -> str:
        return "ok" if good else "MISSED"

    chains = r["chains"]
    lines = [
        f"chains bench: {chains['bag']} ({chains['frames']} frames), {r['samples']} samples per chain "
        f"({r['burn_in']} burn-in), local Ray of {r['workers']} CPUs, median of {r['repeats']} run(s)",
        f"  {'Ray start (once; objslam map pays it per command)':<52} {chains['ray_start_s']:6.1f} s",
        f"  {'chains':>6} {'wall s':>8} {'x one':>6} {'chain s':>8} {'speedup':>8}  converged   objects  runs (wall s)",
    ]
    for row in chains["rows"]:
        verdicts = ",".join({True: "yes", False: "no", None: "-"}[v] for v in row["converged"])
        ratio = f"{row['ratio_to_one']:6.2f}" if row["ratio_to_one"] else "     -"
        speedup = f"{row['speedup']:8.2f}" if row["speedup"] else "       -"
        lines.append(
            f"  {row['chains']:>6} {row['wall_s']:>8.1f} {ratio} {row['chain_s']:>8.1f} {speedup}  {verdicts:<11} "
            f"{','.join(map(str, row['objects'])):<8} {row['wall_s_all']}"
        )
    one_outside = next((row["outside_s"] for row in chains["rows"] if row["chains"] == 1), float("nan"))
    for row in chains["rows"]:
        if row.get("slowest_alone_to_one"):
            lines.append(
                f"  {row['chains']} chains one after another in this process: {row['alone_s']} s; the slowest alone "
                f"takes {row['slowest_alone_to_one']:.2f}x one chain's seconds (its start's work), the parallel "
                f"sampling {row['sampling_to_slowest_alone']:.2f}x the slowest alone (running in parallel); outside "
                f"the chains {row['outside_s']:.1f} s (one chain: {one_outside:.1f} s)"
            )
    two = next((row for row in chains["rows"] if row["chains"] == 2 and row["ratio_to_one"]), None)
    if two is not None:
        lines.append(
            f"  2 chains take {two['ratio_to_one']:.2f}x one chain's wall time   target <= "
            f"{r['target_two_chains_ratio']:g}x: {ok(two['ratio_to_one'] <= r['target_two_chains_ratio'])}"
        )
    batch = r.get("batch")
    if batch is not None:
        batch_name = f"objslam map-batch (local Ray, {batch['workers']} CPUs)"
        lines += [
            f"batch: {', '.join(batch['bags'])}; {batch['chains']} chains of {batch['samples']} samples "
            f"({batch['burn_in']} burn-in) per bag",
            f"  {'objslam map, one bag after another (in-process)':<52} {batch['one_after_another_s']:6.1f} s",
            f"  {batch_name:<52} {batch['map_batch_s']:6.1f} s",
            f"  speedup {batch['speedup']:.2f}x   target >= {r['target_batch_speedup']:g}x: "
            f"{ok(batch['speedup'] >= r['target_batch_speedup'])}",
            f"  same maps both ways: {sum(batch['same_maps'])}/{len(batch['same_maps'])}",
        ]
    return "\n".join(lines)
