"""``objslam figures MAP [--bag BAG]``: the map's top view and image overlays as PNG files."""

from __future__ import annotations

import argparse
from pathlib import Path

from objslam_tools.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "figures",
        help="draw a map: top view (like the paper's Fig. 2) and image overlays (Fig. 3)",
        description=(
            "Top view: objects as circles of their diameter, opacity = existence probability, 2-sigma ellipses, "
            "trajectory, rejected objects dashed and crossed; with a simulated bag also the ground truth. "
            "With a bag that has images: the map's objects projected into chosen images with the map's poses."
        ),
    )
    parser.add_argument("map", metavar="MAP", help="map file written by `objslam map`")
    parser.add_argument("--bag", default=None, help="the bag the map was built from (images, ground truth)")
    parser.add_argument("--out", default=".", metavar="DIR", help="folder for the PNG files (default: .)")
    parser.add_argument(
        "--frames", nargs="+", type=int, default=None, metavar="I", help="image indices to overlay (default: 3 spread)"
    )
    parser.add_argument("--catalog", default=None, help="class catalog for the colours (default: bundled)")
    parser.add_argument("--prefix", default=None, help="file name prefix (default: the map file's name)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # Matplotlib and the scorer load in about three seconds: only for this verb.
    from objslam_common.catalog import load_catalog
    from objslam_mapper.map_file import read_map
    from objslam_tools.figures import write_figures

    if not Path(args.map).is_file():
        raise UserError(f"map file not found: {args.map}")
    built = read_map(args.map)
    catalog = load_catalog(args.catalog)
    prefix = args.prefix or Path(args.map).stem
    for path in write_figures(built, args.out, bag=args.bag, frames=args.frames, catalog=catalog, prefix=prefix):
        print(path)
    return 0
