"""``objslam bench TARGET``: speed measurements (targets live in objslam_tools.bench)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from objslam_tools.bench import targets

    found = targets()
    parser = subparsers.add_parser(
        "bench",
        help="measure speed (e.g. `objslam bench detector`)",
        description="Measure how fast a part of objslam runs. Targets: " + ", ".join(found) + ".",
    )
    sub = parser.add_subparsers(dest="target", metavar="TARGET")
    sub.required = True
    for name, module in found.items():
        target = sub.add_parser(name, help=module.DESCRIPTION, description=module.DESCRIPTION)
        module.add_arguments(target)
        target.set_defaults(func=module.run)
