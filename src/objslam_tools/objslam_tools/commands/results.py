"""``objslam results``: map every scenario with every association, score them, write docs/results.md."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

DEFAULT_SCENARIOS = ("small", "office", "twins", "clutter", "loop")
DEFAULT_ASSOCIATIONS = ("sampler", "greedy", "none", "oracle")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "results",
        help="map the scenarios with every association, score them and write docs/results.md",
        description=(
            "Render the scenarios that are not bundled (into --cache), map each with every association from one "
            "run of the detector, score every map against its ground truth and write the results page "
            "(--out) and the README's table, stating the commit, date and machine. Takes tens of minutes."
        ),
    )
    parser.add_argument(
        "--scenarios", nargs="+", default=list(DEFAULT_SCENARIOS), metavar="NAME[:SEED]", help="scenarios to map"
    )
    parser.add_argument(
        "--associations",
        nargs="+",
        default=list(DEFAULT_ASSOCIATIONS),
        choices=DEFAULT_ASSOCIATIONS,
        metavar="ASSOCIATION",
        help="data associations (default: all four)",
    )
    parser.add_argument(
        "--cameras",
        nargs="+",
        default=["omni"],
        choices=("omni", "pinhole", "fisheye"),
        metavar="CAMERA",
        help="render and map each scenario with these cameras (objslam sim --camera; default omni)",
    )
    parser.add_argument("--cache", type=Path, default=Path("out/bags"), help="where rendered bags are kept")
    parser.add_argument("--out", type=Path, default=Path("docs/results.md"), help="the page to write")
    parser.add_argument("--readme", type=Path, default=Path("README.md"), help="README whose table to update")
    parser.add_argument("--no-readme", action="store_true", help="leave the README alone")
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")
    parser.add_argument(
        "--chains", type=int, default=None, metavar="K", help="chains per map (default: the parameters' sampler.chains)"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from objslam_common.config import default_config_dir, load_config
    from objslam_detector.config import DetectorConfig
    from objslam_mapper.config import MapperConfig
    from objslam_tools.errors import UserError
    from objslam_tools.mapping import with_sampler_overrides
    from objslam_tools.results import Scenario, evaluate, page, provenance, scenario_bag, with_readme_table
    from objslam_tools.sim.scenarios import SCENARIO_NAMES

    scenarios = [dataclasses.replace(Scenario.parse(s), camera=c) for s in args.scenarios for c in args.cameras]
    unknown = [s.name for s in scenarios if s.name not in SCENARIO_NAMES]
    if unknown:
        raise UserError(f"unknown scenario {unknown[0]!r} (one of {', '.join(SCENARIO_NAMES)})")
    repo = Path.cwd()
    readme = None if args.no_readme else args.readme
    if readme is not None and not readme.is_file():
        raise UserError(f"README not found: {readme} (run from the checkout, or pass --no-readme)")
    for target in (args.out, args.cache):
        target.parent.mkdir(parents=True, exist_ok=True)
    config = load_config(MapperConfig, args.params or default_config_dir() / "mapper.yaml", "mapper")
    config = with_sampler_overrides(config, chains=args.chains)
    rows = evaluate(
        scenarios,
        args.associations,
        lambda scenario: scenario_bag(scenario, repo, args.cache),
        config,
        DetectorConfig(),
    )
    command = "objslam " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["results"] else "objslam results"
    args.out.write_text(page(rows, command, provenance(repo)))
    print(f"wrote {args.out}")
    if readme is not None:
        readme.write_text(with_readme_table(readme.read_text(), rows))
        print(f"updated the table of {readme}")
    return 0
