"""``objslam bench TARGET``: speed measurements (targets live in objslam_tools.bench)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from objslam_tools import bench
    from objslam_tools.subcommands import register_group

    register_group(
        subparsers,
        "bench",
        bench,
        "measure speed (e.g. `objslam bench detector`)",
        "Measure how fast a part runs",
        metavar="TARGET",
    )
