"""``objslam bench mapper`` on the small bag: the table has every row the issue asks for (no timing asserts)."""

from __future__ import annotations

import json
import subprocess
import sys

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
