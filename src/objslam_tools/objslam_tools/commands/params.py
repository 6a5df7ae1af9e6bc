"""``objslam params [NODE]``: a node's default parameter file, or its table, made from the code."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "params",
        help="print a node's default parameter file (or table); --write regenerates config/*.yaml and the docs",
        description=(
            "Print the default ROS 2 parameter file of a node, made from the settings' one description in "
            "the code ([expert] marks what only someone who knows the method should change), or its "
            "markdown table. --write regenerates config/*.yaml and the tables of docs/design.md."
        ),
    )
    parser.add_argument("node", nargs="?", choices=("mapper", "detector"), help="the node (default: mapper)")
    parser.add_argument("--markdown", action="store_true", help="print the markdown table instead")
    parser.add_argument(
        "--write", metavar="REPO", nargs="?", const=".", default=None, help="regenerate the files of this checkout"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from objslam_tools.errors import UserError
    from objslam_tools.params import node_parameter_file, parameter_table, write_all

    if args.write is not None:
        repo = Path(args.write)
        if not (repo / "config").is_dir():
            raise UserError(f"{repo} is not an objslam checkout (no config/ folder)")
        written = write_all(repo)
        print("\n".join(f"wrote {p}" for p in written) or "everything was up to date")
        return 0
    node = args.node or "mapper"
    print(parameter_table(node) if args.markdown else node_parameter_file(node), end="")
    return 0
