"""``objslam diagnose NAME``: measurements of the method (modules of objslam_tools.diagnose)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from objslam_tools import diagnose
    from objslam_tools.subcommands import register_group

    register_group(
        subparsers,
        "diagnose",
        diagnose,
        "measure the method on simulated bags (e.g. `objslam diagnose error-budget BAG`)",
        "Diagnostics of the method on simulated bags",
    )
