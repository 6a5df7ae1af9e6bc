"""``objslam bench mapper`` on the small bag: the table has every row the issue asks for (no timing asserts)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

ROWS = (
    "detector (not in the map build)",
    "map build wall time",
    "map build CPU time",
    "samples per second",
    "time per phase",
    "tracklets",
    "proposals and chain bookkeeping",
    "screens (conditional object solves)",
    "graph solves",
    "marginals (kept states)",
    "Algorithm 1 bookkeeping",
    "distinct associations visited",
    "naive GTSAM solve",
    "naive chain (one solve per sample)",
    "speedup over naive",
)


BENCH = (sys.executable, "-m", "objslam_tools.cli", "bench", "mapper")


def _phase_keys():
    from objslam_tools.bench.mapper import PHASES

    return [key for key, _ in PHASES]


PHASE_KEYS = _phase_keys()


def bench(repo_root, *extra):
    return subprocess.run(
        [*BENCH, "bags/small", "--samples", "200", "--burn-in", "50", "--no-scaling", "--naive-seconds", "1", *extra],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
        cwd=repo_root,
    )


def test_bench_mapper_prints_every_row(repo_root):
    result = bench(repo_root)
    assert result.returncode == 0, result.stderr
    for row in ROWS:
        assert row in result.stdout, row
    assert "5 objects" in result.stdout  # bags/small holds one object of each class


def test_bench_mapper_json_and_user_errors(repo_root, tmp_path):
    result = bench(repo_root, "--json", "--naive-seconds", "0")
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["samples"] == 200 and data["wall_s"] > 0 and "naive" not in data
    assert set(data["phases_s"]) >= {"tracklets", "screening", "solving_during_sampling", "marginals"}
    bad = subprocess.run(
        [*BENCH, str(tmp_path), "--no-scaling"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert bad.returncode == 2 and "not a rosbag2 directory" in bad.stderr and "Traceback" not in bad.stderr


def test_the_scaling_table_splits_the_growth_into_solves_and_time_per_solve():
    from objslam_tools.bench.mapper import _table

    base = json.loads(bench_json_stub())
    rows = [
        {"factor": f, "frames": 400 * f, "measurements": 5000 * f, "tracklets": 40 + f, "wall_s": 8.0 * f**1.4,
         "cpu_s": 8.0 * f**1.4, "objects": 12, "graph_solves": 45 * f, "seconds_per_graph_solve": 0.09 * f**0.4}
        for f in (1, 2, 4)
    ]  # fmt: skip
    base["scaling"] = {
        "samples": 1000,
        "rows": rows,
        "growth_exponent_wall": 1.4,
        "growth_exponent_cpu": 1.4,
        "growth_exponent_graph_solves": 1.0,
        "growth_exponent_per_graph_solve": 0.4,
    }
    table = _table(base)
    assert "solves  s/solve" in table and "   180    0.157" in table
    assert "k = 1.40 wall" in table and "MISSED" in table
    assert "graph solves ~ frames^1.00, time per graph solve ~ frames^0.40" in table


def bench_json_stub():
    return json.dumps(
        {
            "bag": "b", "frames": 1, "measurements": 1, "tracklets": 1, "samples": 2, "burn_in": 1, "detector_s": 0.0,
            "wall_s": 1.0, "cpu_s": 1.0, "samples_per_s": 2.0, "target_wall_s": 60.0, "target_speedup": 20.0,
            "phases_s": {key: 0.0 for key in PHASE_KEYS}, "graph_solves": 1, "screens": 1, "object_solves": 1,
            "clutter_solves": 1, "marginal_solves": 1, "distinct_associations_visited": 1, "acceptance_rate": 0.5,
            "objects": 1, "rejected": 0,
        }
    )  # fmt: skip


def test_the_scaling_runs_build_the_real_workload_unless_told_otherwise():
    import argparse

    from objslam_tools.bench.mapper import add_arguments, scaling_chain

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert scaling_chain(parser.parse_args([])) == (6000, 2500)
    assert scaling_chain(parser.parse_args(["--samples", "300", "--burn-in", "100"])) == (300, 100)
    assert scaling_chain(parser.parse_args(["--scaling-samples", "1000"])) == (1000, 250)


def test_cached_detections_are_keyed_on_the_detector():
    import dataclasses

    from objslam_common.catalog import load_catalog
    from objslam_detector.config import DetectorConfig
    from objslam_tools.bench.mapper import detector_fingerprint

    config, catalog = DetectorConfig(), load_catalog()
    assert detector_fingerprint(config, catalog) == detector_fingerprint(DetectorConfig(), load_catalog())
    other = dataclasses.replace(config, image_transport="raw")
    assert detector_fingerprint(other, catalog) != detector_fingerprint(config, catalog)


def test_time_naive_solves_counts_what_it_timed():
    from objslam_tools.bench._naive import time_naive_solves
    from objslam_tools.errors import ToolsError
    from tests.objslam_mapper.graph.test_gtsam_backend import make_problem

    problem, groups = make_problem(8)
    seconds, count = time_naive_solves(problem, [groups[:1], groups[1:]], max_seconds=60.0)
    assert count == 2 and seconds > 0.0
    assert time_naive_solves(problem, [groups, groups], max_seconds=0.0)[1] == 1
    with pytest.raises(ToolsError):
        time_naive_solves(problem, [], max_seconds=1.0)
