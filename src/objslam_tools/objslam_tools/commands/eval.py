"""``objslam eval MAP [MAP ...] --bag BAG``: score maps against a simulated bag's ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from objslam_tools.errors import UserError

# Shown in --help without importing the scorer (objslam_tools.evaluate loads SciPy's stats
# and optimize, about a second that every objslam verb would pay at start); a test keeps it
# equal to evaluate.DEFAULT_GATE_M.
GATE_HELP_DEFAULT_M = 0.5


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "eval",
        help="score maps against a simulated bag's ground truth",
        description=(
            "Align each map's trajectory to /ground_truth/odom (least-squares SE(2)), match objects per class "
            "(Hungarian, xy gate) and print precision, recall, position/size errors, NEES, trajectory and raw "
            "odometry ATE. Several maps are shown side by side, one column each."
        ),
    )
    parser.add_argument("maps", nargs="+", metavar="MAP", help="map file(s) written by `objslam map`")
    parser.add_argument("--bag", required=True, help="the simulated bag the maps were built from")
    parser.add_argument(
        "--label", nargs="+", default=None, metavar="NAME", help="column names, one per map (default: file names)"
    )
    parser.add_argument(
        "--gate", type=float, default=None, metavar="M", help=f"xy match gate in metres (default {GATE_HELP_DEFAULT_M})"
    )
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON instead of tables")
    parser.set_defaults(func=run)


def _names(paths: list[str], labels: list[str] | None) -> list[str]:
    if labels is not None:
        if len(labels) != len(paths):
            raise UserError(f"--label gives {len(labels)} names for {len(paths)} maps")
        return labels
    stems = [Path(p).stem for p in paths]
    # Same file names in different folders: fall back to the paths as given.
    return stems if len(set(stems)) == len(stems) else list(paths)


def run(args: argparse.Namespace) -> int:
    from objslam_mapper.map_file import read_map
    from objslam_tools.evaluate import DEFAULT_GATE_M, format_report, load_reference, score_map

    names = _names(args.maps, args.label)
    gate_m = DEFAULT_GATE_M if args.gate is None else args.gate
    if gate_m <= 0:
        raise UserError(f"--gate must be positive, got {gate_m}")
    built = []
    for path in args.maps:
        if not Path(path).is_file():
            raise UserError(f"map file not found: {path}")
        built.append(read_map(path))
    reference = load_reference(args.bag)
    scores = [score_map(m, reference, gate_m=gate_m, name=n) for m, n in zip(built, names, strict=True)]
    if args.json:
        payload = {"bag": str(args.bag), "maps": [s.to_dict() for s in scores]}
        print(json.dumps(payload, indent=2))
    else:
        print(
            f"bag {args.bag}: {len(reference.ground_truth.objects)} real objects, "
            f"{len(reference.ground_truth.distractors)} distractors"
        )
        print(format_report(scores))
    return 0
