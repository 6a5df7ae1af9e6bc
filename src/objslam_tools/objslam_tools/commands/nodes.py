"""``objslam detector`` and ``objslam mapper``: run the nodes, as ``ros2 run`` would.

Everything after the verb goes to the node, e.g.
``objslam detector --ros-args --params-file config/detector.yaml -p use_sim_time:=true``.
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

NODES = {
    "detector": ("objslam_detector.ros.node", "the detector node: images -> /objslam/slices"),
    "mapper": ("objslam_mapper.ros.node", "the mapper node: buffers odometry and slices, serves /objslam/build_map"),
}


def register(subparsers: argparse._SubParsersAction) -> None:
    for verb, (module, help_text) in NODES.items():
        parser = subparsers.add_parser(verb, help=f"run {help_text}", add_help=False)
        parser.add_argument("node_args", nargs=argparse.REMAINDER, help="ROS arguments (--ros-args ...)")
        parser.set_defaults(func=_runner(verb, module, help_text), passthrough=True)


HELP = """usage: objslam {verb} [--ros-args --params-file FILE -p NAME:=VALUE ...]

Run {help_text} (as `ros2 run objslam_{package} {verb}` would).
Everything after the verb goes to the node: ROS 2 arguments after --ros-args.

  objslam {verb} --ros-args --params-file config/{verb}.yaml -p use_sim_time:=true

Its parameters, each with its description: `objslam params {verb}` (or config/{verb}.yaml);
all of them are listed in docs/design.md.
"""


def _runner(verb: str, module: str, help_text: str):
    def run(args: argparse.Namespace) -> int:
        from objslam_tools.errors import UserError

        ros_args = args.node_args
        before_ros = ros_args[: ros_args.index("--ros-args")] if "--ros-args" in ros_args else ros_args
        if {"-h", "--help"} & set(before_ros):
            print(HELP.format(verb=verb, help_text=help_text, package=verb), end="")
            return 0
        for k, arg in enumerate(ros_args[:-1]):
            if arg == "--params-file" and not Path(ros_args[k + 1]).is_file():
                raise UserError(f"--params-file {ros_args[k + 1]}: no such file")
        main = importlib.import_module(module).main
        return int(main(["objslam", *ros_args]) or 0)

    return run
