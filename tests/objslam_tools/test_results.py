"""``objslam results``: the page and the README's table, from maps scored against the ground truth."""

from __future__ import annotations

import subprocess

import pytest

from objslam_tools.errors import UserError
from objslam_tools.results import README_BEGIN, README_END, Row, Scenario, page, provenance, table, with_readme_table
from tests.conftest import objslam_cmd

GOOD = {
    "map_objects": 5,
    "truth_objects": 5,
    "precision": 1.0,
    "recall": 1.0,
    "xy_error_median_m": 0.01,
    "diameter_error_mean_m": 0.004,
    "height_error_mean_m": 0.006,
    "trajectory_ate_m": 0.03,
    "odometry_ate_m": 0.08,
    "distractors_as_objects": 0,
    "overlapping_pairs": 0,
}


def test_a_row_meets_the_targets_one_by_one():
    assert Row("small", "sampler", GOOD, 5.0).meets() == [True] * 7
    worse = {**GOOD, "precision": 0.8, "xy_error_median_m": 0.06, "trajectory_ate_m": 0.05, "overlapping_pairs": 1}
    assert Row("small", "sampler", worse, 5.0).meets() == [False, True, False, True, False, True, False]
    # An ATE of 2 cm or less passes whatever the odometry's.
    assert Row("s", "a", {**GOOD, "trajectory_ate_m": 0.015, "odometry_ate_m": 0.01}, 1.0).meets()[4]
    none = {**GOOD, "precision": None, "recall": None, "xy_error_median_m": None}
    assert Row("s", "a", none, 1.0).meets()[:3] == [False, False, False]


def test_scenarios_name_their_seed_unless_bundled():
    assert Scenario.parse("small") == Scenario("small", 2) and Scenario.parse("small").label == "small"
    assert Scenario.parse("twins") == Scenario("twins", 1) and Scenario.parse("twins").label == "twins:1"
    assert Scenario.parse("office:7").label == "office:7"
    with pytest.raises(UserError):
        Scenario.parse("office:x")


def test_the_readme_table_is_replaced_between_its_markers():
    rows = [Row("small", "sampler", GOOD, 5.0), Row("small", "none", {**GOOD, "precision": 0.5}, 1.0)]
    readme = f"# objslam\n\ntext\n\n{README_BEGIN}\nold\n{README_END}\n\nmore\n"
    updated = with_readme_table(readme, rows)
    assert "old" not in updated and updated.endswith(f"{README_END}\n\nmore\n")
    assert "| small | sampler | 5/5 |" in updated and "| none |" not in updated
    assert "| 7/7 |" in table(rows) and "| 6/7 |" in table(rows)
    with pytest.raises(UserError):
        with_readme_table("# no markers\n", rows)


@pytest.mark.slow
def test_the_command_writes_a_page_that_names_its_command_and_commit(tmp_path):
    out = tmp_path / "results.md"
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n{README_BEGIN}\n{README_END}\n")
    args = ["results", "--scenarios", "small", "--associations", "none", "--out", str(out), "--readme", str(readme)]
    done = subprocess.run(objslam_cmd(*args), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    assert "objslam results --scenarios small --associations none" in text and "commit `" in text
    assert "| small | none |" in text
    assert "| small |" not in readme.read_text()  # the README shows the sampler's rows only
    bad = subprocess.run(objslam_cmd("results", "--scenarios", "nope", "--no-readme"), capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown scenario 'nope'" in bad.stderr


def test_a_camera_page_gives_the_seen_recall_and_says_why_rows_miss():
    seen = {**GOOD, "recall": 0.4, "recall_seen": 1.0, "seen_objects": 2}
    missing = {**seen, "precision": 0.5}
    rows = [
        Row("small", "sampler", GOOD, 5.0),
        Row("small", "sampler", seen, 5.0, "pinhole"),
        Row(
            "small",
            "sampler",
            missing,
            5.0,
            "fisheye",
            ("false positive red (P 1.00), 1.40 m from the nearest real red",),
        ),
    ]
    # The recall target is judged on the objects the camera saw.
    assert rows[1].meets() == [True] * 7
    text = page(rows, "objslam results --cameras omni pinhole fisheye", "commit `abc`")
    assert "| small | pinhole | sampler | 5/5 | 1.00 | 0.40 | 1.00 of 2 |" in text
    assert "**small (fisheye), sampler** misses: precision >= 0.95.\n  - false positive red" in text
    assert "small (pinhole)" not in text.split("## Rows that miss a target")[1]


def test_rows_of_several_chains_say_how_far_the_chains_agree():
    four = {**GOOD, "chains": 4, "rhat_max": 1.004, "ess_min": 812.4, "chains_agreeing": 3, "overlapping_pairs": 1}
    slow = {**four, "rhat_max": 1.27, "ess_min": 12.0, "chains_agreeing": 4, "converged": False, "draws_needed": 120000}
    stuck = {**four, "rhat_max": float("inf"), "ess_min": 4.0, "chains_agreeing": 2, "converged": False}
    rows = [
        Row("office", "sampler", {**four, "converged": True}, 30.0),
        Row("twins", "sampler", slow, 40.0),
        Row("clutter", "sampler", stuck, 50.0),
        Row("office", "greedy", {**GOOD, "chains": None}, 3.0),
    ]
    text = table(rows)
    assert "| R-hat max | ESS min | chains agreeing | draws needed |" in text
    assert "| 0 | 1 | 1.00 | 812 | 3 of 4 | enough | 6/7 | 30 |" in text  # distractors, duplicates, chains
    assert "| 1.27 | 12 | 4 of 4 | 120000 | 6/7 | 40 |" in text  # too few samples: how many would do
    assert "| inf | 4 | 2 of 4 | stuck | 6/7 | 50 |" in text
    assert "| 0 | 0 | - | - | - | - | 7/7 | 3 |" in text
    assert "draws needed: `enough` where the chains converged" in page(rows, "objslam results", "commit `abc`")
    assert "R-hat" not in table([Row("office", "sampler", {**GOOD, "chains": 1}, 30.0)])
    assert "draws needed" not in page([Row("office", "sampler", {**GOOD, "chains": 1}, 30.0)], "c", "o")


def test_chain_metrics_count_the_chains_that_agree_with_the_pooled_map():
    from types import SimpleNamespace

    from objslam_tools.results import chain_metrics

    def identity(p, by_chain):
        return SimpleNamespace(existence_probability=p, existence_by_chain=by_chain)

    built = SimpleNamespace(
        objects=(identity(0.9, (1.0, 1.0, 0.6)), identity(0.7, (1.0, 0.2, 0.9))),
        rejected=(identity(0.3, (0.0, 0.1, 0.8)),),
        diagnostics={"convergence": {"rhat_max": "inf", "ess_bulk_min": 4.0, "converged": False, "draws_needed": None}},
    )
    m = chain_metrics(built, 3)
    assert m["chains_agreeing"] == 1 and m["rhat_max"] == float("inf") and m["ess_min"] == 4.0
    assert m["converged"] is False and m["draws_needed"] is None
    assert chain_metrics(built, 0) == {"chains": None}


def test_provenance_names_the_commit_and_ignores_the_pages_a_run_writes(tmp_path):
    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    git("init", "-q")
    (tmp_path / "docs").mkdir()
    for name in ("docs/chains.md", "README.md", "CHANGELOG.md", "code.py"):
        (tmp_path / name).write_text("one\n")
    git("add", "-A")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    assert "uncommitted" not in provenance(tmp_path)
    (tmp_path / "docs/chains.md").write_text("two\n")
    (tmp_path / "README.md").write_text("two\n")
    (tmp_path / "CHANGELOG.md").write_text("two\n")
    assert "uncommitted" not in provenance(tmp_path)  # a page an earlier run regenerated, the changelog
    (tmp_path / "code.py").write_text("two\n")
    assert "with uncommitted changes" in provenance(tmp_path)
