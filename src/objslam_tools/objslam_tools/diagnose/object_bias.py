"""The detector's per-object bias: the defaults of `solver.error_covariance.*_bias_share`.

Usage: objslam diagnose object-bias BAG [BAG ...] [--params FILE]

For each simulated BAG: detect, chain, give every slice the real object that explains it
(the oracle of `objslam map --association oracle`), and take each slice's error at the
ground truth (ground-truth pose and object), whitened by the slice's configured stddev.
The mean of one object's whitened errors is its bias (hundreds of slices average the white
noise away; their standard deviation is printed beside it); printed per object with the
mean over the bag's objects (a bias all of them share), then the root mean square over
the objects of all BAGs per component: the bias share of objslam_mapper.graph.error_covariance
(the stddev of an error common to all slices of an object, in units of the slices'
configured stddev). A measurement of the detector on simulated bags.
"""

from __future__ import annotations

import argparse

import numpy as np

from objslam_common.catalog import load_catalog
from objslam_common.config import default_config_dir, load_config
from objslam_common.geometry import wrap_angle
from objslam_mapper.config import MapperConfig
from objslam_mapper.model.slice_model import BEARING, COMPONENTS, censor, predict_reduced


def object_biases(bag_path: str, config: MapperConfig) -> list[tuple[str, int, np.ndarray, np.ndarray]]:
    """(label, slice count, mean and standard deviation of the whitened errors (4,)) per real object of the bag."""
    # The oracle map loads the scorer and SciPy (about a second); every objslam verb imports
    # this module to build its parser (objslam_tools.subcommands), so only when run.
    from objslam_tools.oracle_map import oracle_problem

    problem, reference, truth_ids, groups = oracle_problem(bag_path, config, load_catalog(config.catalog_file or None))
    truth = {o.id: o for o in reference.ground_truth.objects}
    out = []
    for object_id, members in zip(truth_ids, groups, strict=True):
        index = np.array(members)
        poses = reference.ground_truth_track.interpolate(problem.stamps_ns[problem.measurement_pose[index]])
        count = len(index)
        obj = truth[object_id]
        pred = predict_reduced(
            poses, np.tile(obj.position_m, (count, 1)), np.tile(obj.size_m, (count, 1)), reference.ground_truth.mount
        )
        error = pred.values - problem.measurements[index].T
        error[BEARING] = wrap_angle(error[BEARING])
        whitened = error / problem.measurement_stddev[index].T
        whitened *= censor(whitened, problem.measurement_bounds[index])
        out.append((obj.label, count, whitened.mean(axis=1), whitened.std(axis=1)))
    return out


DESCRIPTION = "the detector's per-object bias: the defaults of solver.error_covariance.*_bias_share"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bags", nargs="+", metavar="BAG", help="simulated bags (with ground truth)")
    parser.add_argument("--params", metavar="FILE", default=None, help="mapper parameters (default config/mapper.yaml)")


def run(args: argparse.Namespace) -> int:
    config = load_config(MapperConfig, args.params or default_config_dir() / "mapper.yaml", "mapper")
    means = []
    header = "  ".join(f"{c:>16s}" for c in COMPONENTS)
    for bag in args.bags:
        print(f"{bag}: mean / standard deviation of each object's whitened errors\n  label   slices  {header}")
        bag_means = []
        for label, count, mean, spread in object_biases(bag, config):
            bag_means.append(mean)
            cells = "  ".join(f"{m:7.3f} / {d:6.3f}" for m, d in zip(mean, spread, strict=True))
            print(f"  {label:6s} {count:7d}  {cells}")
        # What all objects share: a bias of the detector in this scene, which moves the map's scale.
        common = np.mean(bag_means, axis=0)
        print("  mean over the objects  " + "  ".join(f"{m:16.3f}" for m in common))
        means += bag_means
    rms = np.sqrt(np.mean(np.square(means), axis=0))
    print(f"bias share (root mean square of the means over {len(means)} objects):")
    print("  " + "  ".join(f"{c} {v:.3f}" for c, v in zip(COMPONENTS, rms, strict=True)))
    return 0
