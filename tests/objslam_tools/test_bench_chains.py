"""``objslam bench chains`` on the small bag: its rows and figures, no timing asserts."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from objslam_tools.bench.chains import format_table

BENCH = (sys.executable, "-m", "objslam_tools.cli", "bench", "chains", "bags/small")
SHORT = ("--samples", "200", "--burn-in", "50", "--no-batch", "--cache-dir")


def _bench(repo_root, tmp_path, *extra):
    return subprocess.run(
        [*BENCH, *SHORT, str(tmp_path), *extra], capture_output=True, text=True, timeout=300, cwd=repo_root
    )


def test_one_and_two_chains_are_timed_side_by_side(repo_root, tmp_path):
    done = _bench(repo_root, tmp_path, "--chains", "1,2", "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    rows = {row["chains"]: row for row in result["chains"]["rows"]}
    assert set(rows) == {1, 2}
    assert rows[1]["ratio_to_one"] == 1.0 and rows[1]["converged"] == [None]
    two = rows[2]
    assert two["ratio_to_one"] == pytest.approx(two["wall_s"] / rows[1]["wall_s"])
    assert two["speedup"] == pytest.approx(2 * rows[1]["wall_s"] / two["wall_s"])
    assert two["converged"] in ([True], [False]) and two["objects"] == [5]
    assert result["chains"]["ray_start_s"] > 0.0
    # The same two chains one after another: each timed alone, the wall time split into the
    # slowest chain's own work and what running them in parallel adds.
    assert len(two["alone_s"]) == 2 and two["slowest_alone_s"] == max(two["alone_s"])
    assert two["slowest_alone_to_one"] == pytest.approx(two["slowest_alone_s"] / rows[1]["chain_s"])
    assert two["sampling_to_slowest_alone"] == pytest.approx(two["sampling_s"] / two["slowest_alone_s"])
    for row in rows.values():
        assert 0.0 < row["outside_s"] < row["wall_s"] and row["sampling_s"] >= row["chain_s"] / row["chains"] * 0.5
    assert "alone_s" not in rows[1]
    # The table printed without --json, from the same figures (one bench run for both: they take seconds).
    table = format_table(result)
    assert "2 chains take" in table and "target <= 1.2x" in table and "Ray start" in table
    assert "2 chains one after another" in table and "the slowest alone" in table


@pytest.mark.parametrize(("args", "message"), [(("--chains", "0,2"), "at least 1"), (("--chains", "x"), "1,2,4")])
def test_bad_counts_are_one_line(repo_root, tmp_path, args, message):
    done = _bench(repo_root, tmp_path, *args)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr
