"""``objslam diagnose NAME``: measurements of the method (modules of objslam_tools.diagnose)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from objslam_tools.diagnose import diagnostics

    found = diagnostics()
    parser = subparsers.add_parser(
        "diagnose",
        help="measure the method on simulated bags (e.g. `objslam diagnose error-budget BAG`)",
        description="Diagnostics of the method on simulated bags: " + ", ".join(found) + ".",
    )
    sub = parser.add_subparsers(dest="diagnostic", metavar="NAME")
    sub.required = True
    for name, module in found.items():
        target = sub.add_parser(name, help=module.DESCRIPTION, description=module.DESCRIPTION)
        module.add_arguments(target)
        target.set_defaults(func=module.run)
