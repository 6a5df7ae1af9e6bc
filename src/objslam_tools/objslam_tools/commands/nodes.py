"""``objslam detector`` and ``objslam mapper``: run the nodes, as ``ros2 run`` would.

Everything after the verb goes to the node, e.g.
``objslam detector --ros-args --params-file config/detector.yaml -p use_sim_time:=true``.
"""

from __future__ import annotations

import argparse
import importlib

NODES = {
    "detector": ("objslam_detector.ros.node", "the detector node: images -> /objslam/slices"),
    "mapper": ("objslam_mapper.ros.node", "the mapper node: buffers odometry and slices, serves /objslam/build_map"),
}


def register(subparsers: argparse._SubParsersAction) -> None:
    for verb, (module, help_text) in NODES.items():
        parser = subparsers.add_parser(verb, help=f"run {help_text}", add_help=False)
        parser.add_argument("node_args", nargs=argparse.REMAINDER, help="ROS arguments (--ros-args ...)")
        parser.set_defaults(func=_runner(module), passthrough=True)


def _runner(module: str):
    def run(args: argparse.Namespace) -> int:
        main = importlib.import_module(module).main
        return int(main(["objslam", *args.node_args]) or 0)

    return run
