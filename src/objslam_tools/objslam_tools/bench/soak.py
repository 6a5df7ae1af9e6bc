"""``objslam bench soak``: the ROS path for many laps: memory stays bounded, every build answers.

The detector and mapper nodes run as ``objslam detector`` / ``objslam mapper`` processes in
a private ROS domain; ``objslam play BAG --loop`` plays the bag over and over (the mapper
clears its buffers when time jumps back) and once per lap ``objslam call build-map``
builds the map. After each build the mapper's resident memory (VmRSS) is read from /proc.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import yaml

DESCRIPTION = "the nodes on a bag played in a loop, a build per lap: mapper memory and answers"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bag", default="bags/small", help="the bag to loop (default bags/small)")
    parser.add_argument("--laps", type=int, default=6, metavar="N", help="laps, one build each (default 6)")
    parser.add_argument("--samples", type=int, default=600, help="samples per build (default 600)")
    parser.add_argument("--burn-in", type=int, default=200, help="burn-in per build (default 200)")
    parser.add_argument(
        "--domain-id",
        type=int,
        default=None,
        metavar="N",
        help="ROS domain of the soak's nodes (default: one of its own in 150-229, apart from nodes already running)",
    )
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON")


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "objslam_tools.cli", *args]


def run(args: argparse.Namespace) -> int:
    from objslam_tools.bag import open_bag
    from objslam_tools.errors import UserError

    if args.laps < 1 or args.burn_in >= args.samples:
        raise UserError("--laps must be >= 1 and --burn-in below --samples")
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise UserError(f"--domain-id must be in 0-232, got {args.domain_id}")
    if not Path("/proc/self/status").exists():
        raise UserError("objslam bench soak reads memory from /proc: Linux only")
    bag = open_bag(args.bag)
    lap_s = (bag.end_ns - bag.start_ns) * 1e-9
    domain = args.domain_id if args.domain_id is not None else 150 + os.getpid() % 80
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    quiet = {"env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    mapper = subprocess.Popen(_cli("mapper", "--ros-args", "-p", "sampler.chains:=1"), **quiet)  # type: ignore[call-overload]
    nodes = [mapper, subprocess.Popen(_cli("detector", "--ros-args", "-p", "reliable_images:=true"), **quiet)]  # type: ignore[call-overload]
    rows = []
    try:
        time.sleep(3.0)  # discovery
        nodes.append(subprocess.Popen(_cli("play", str(bag.path), "--loop"), **quiet))  # type: ignore[call-overload]
        started = time.monotonic()
        for lap in range(1, args.laps + 1):
            # Build two thirds into each lap: most of it buffered, the loop not yet back.
            time.sleep(max(0.0, started + (lap - 1 / 3) * lap_s - time.monotonic()))
            t0 = time.monotonic()
            request = ["--samples", str(args.samples), "--burn-in", str(args.burn_in), "--timeout", "600"]
            call = subprocess.run(
                _cli("call", "build-map", *request), env=env, capture_output=True, text=True, timeout=700
            )
            answer = yaml.safe_load(call.stdout) if call.stdout else {}
            rows.append(
                {
                    "lap": lap,
                    "answered": bool(answer),
                    "success": bool(answer.get("success")),
                    "objects": int(answer.get("object_count", 0)),
                    # why a build failed, or how it ended: a soak's row must say
                    "message": str(answer.get("message", call.stderr.strip()[-300:])),
                    "build_s": round(time.monotonic() - t0, 2),
                    "mapper_rss_mb": round(_rss_mb(mapper.pid), 1),
                }
            )
            if not args.json:
                r = rows[-1]
                print(
                    f"lap {lap:3d}: answered {r['answered']!s:5s} success {r['success']!s:5s} "
                    f"objects {r['objects']:3d}  build {r['build_s']:6.2f} s  mapper RSS {r['mapper_rss_mb']:7.1f} MB"
                    + ("" if r["success"] else f"  ({r['message']})"),
                    flush=True,
                )
    finally:
        for proc in reversed(nodes):
            proc.terminate()
        for proc in nodes:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
    rss = [r["mapper_rss_mb"] for r in rows]
    summary = {
        "bag": str(bag.path),
        "laps": args.laps,
        "answered": sum(r["answered"] for r in rows),
        "succeeded": sum(r["success"] for r in rows),
        "rss_first_mb": rss[0],
        "rss_last_mb": rss[-1],
        "rss_max_mb": max(rss),
        "rows": rows,
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"{summary['answered']}/{args.laps} builds answered, {summary['succeeded']} succeeded; mapper RSS "
            f"{rss[0]:.1f} MB after the first, {rss[-1]:.1f} MB after the last, {max(rss):.1f} MB at most"
        )
    return 0 if summary["answered"] == args.laps else 1
