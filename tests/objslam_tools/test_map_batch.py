"""``objslam map-batch``: many bags as one job, each map the one ``objslam map`` writes."""

from __future__ import annotations

import shutil
import subprocess

import pytest
import yaml

from tests.conftest import BAGS, objslam_cmd

CHAIN = ("--samples", "200", "--burn-in", "50")


def _run(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(objslam_cmd(*args), capture_output=True, text=True, timeout=timeout)


def _content(path):
    content = yaml.safe_load(path.read_text())
    for timing in ("timings_s", "wall_time_s"):
        content["diagnostics"].pop(timing, None)
    return content


@pytest.fixture(scope="module")
def two_bags(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bags")
    shutil.copytree(BAGS / "small", folder / "small")
    shutil.copytree(BAGS / "small", folder / "again")
    return folder


def test_two_bags_in_one_job_give_the_maps_of_objslam_map(two_bags, tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"mapper": {"ros__parameters": {"sampler": {"samples": 200, "burn_in": 50}}}}))
    out = tmp_path / "maps"
    batch = _run(
        "map-batch",
        str(two_bags / "small"),
        str(two_bags / "again"),
        "--out",
        str(out),
        "--chains",
        "2",
        "--params",
        str(params),
    )
    assert batch.returncode == 0, batch.stderr
    lines = batch.stdout.splitlines()
    assert lines[0].split()[:4] == ["bag", "objects", "rejected", "converged"]
    assert [line.split()[0] for line in lines[1:3]] == ["small", "again"]
    assert "2 bags in" in batch.stdout
    assert "sampling" in batch.stderr  # progress while the chains ran

    single = tmp_path / "single.yaml"
    alone = _run("map", str(two_bags / "small"), "--out", str(single), "--chains", "2", *CHAIN)
    assert alone.returncode == 0, alone.stderr
    assert _content(out / "small.yaml") == _content(single)
    assert _content(out / "again.yaml")["objects"] == _content(single)["objects"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("map-batch", str(BAGS / "small"), str(BAGS / "small")), "same folder name"),
        (("map-batch", str(BAGS / "nothing-here")), "nothing-here"),
        (("map-batch", str(BAGS / "small"), "--chains", "0"), "--chains must be >= 1"),
    ],
)
def test_user_errors_are_one_line_before_any_work(args, message, tmp_path):
    done = _run(*args, "--out", str(tmp_path / "maps"), timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert message in done.stderr
    assert not (tmp_path / "maps").exists() or not any((tmp_path / "maps").iterdir())


def test_the_biggest_bag_is_prepared_first():
    from types import SimpleNamespace

    from objslam_tools.commands.map_batch import biggest_first

    bags = [SimpleNamespace(message_count=n) for n in (300, 2000, 300, 900)]
    assert biggest_first(bags) == [1, 3, 0, 2]
