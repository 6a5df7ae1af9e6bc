"""Chains on Ray: which cluster, and the same map on a real local Ray cluster as in one process."""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from objslam_mapper.config import ParallelConfig
from objslam_mapper.inference.chains import InProcess
from objslam_mapper.parallel import RayRunner, chain_runner, ray_address
from tests.conftest import BAGS, objslam_cmd


def test_the_address_comes_from_the_command_the_parameter_the_environment_else_local(monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert ray_address(ParallelConfig()) is None
    monkeypatch.setenv("RAY_ADDRESS", "10.0.0.9:6379")
    assert ray_address(ParallelConfig()) == "10.0.0.9:6379"
    assert ray_address(ParallelConfig(ray_address="10.0.0.5:6379")) == "10.0.0.5:6379"
    assert ray_address(ParallelConfig(ray_address="10.0.0.5:6379"), "auto") == "auto"


def test_one_chain_or_the_inprocess_backend_runs_here():
    assert isinstance(chain_runner(ParallelConfig(), 1), InProcess)
    assert isinstance(chain_runner(ParallelConfig(backend="inprocess"), 4), InProcess)
    runner = chain_runner(ParallelConfig(workers=2), 4, "127.0.0.1:1")
    assert isinstance(runner, RayRunner) and runner.address == "127.0.0.1:1" and runner.workers == 2


def test_parallel_config_validates():
    with pytest.raises(ValueError, match="backend"):
        ParallelConfig(backend="threads")
    with pytest.raises(ValueError, match="workers"):
        ParallelConfig(workers=-1)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def ray_env() -> Iterator[dict[str, str]]:
    """Token authentication as ``ray start`` turns it on, with a token of this test's own, and a
    Ray temp dir of its own: there ``ray start`` leaves the address that a bare ``ray.init()``
    joins, as it would on a user's machine (and the path of Ray's sockets stays short)."""
    temp_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    auth = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    try:
        yield {**env, **auth, "RAY_TMPDIR": temp_dir, "RAY_USAGE_STATS_ENABLED": "0"}
    finally:
        shutil.rmtree(temp_dir, ignore_errors=True)


@pytest.fixture(scope="module")
def ray_cluster(ray_env):
    """A real local Ray cluster of 2 CPUs (``ray start --head``), stopped after the tests."""
    port = _free_port()
    ray = str(Path(sys.executable).with_name("ray"))
    head = subprocess.Popen(
        [
            ray,
            "start",
            "--head",
            "--block",
            "--num-cpus",
            "2",
            "--port",
            str(port),
            "--include-dashboard",
            "false",
            "--disable-usage-stats",
        ],
        env=ray_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    address = f"127.0.0.1:{port}"
    deadline = time.monotonic() + 90
    while True:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                break
        if head.poll() is not None or time.monotonic() > deadline:
            head.kill()
            pytest.fail(f"ray start did not come up: {head.stdout.read() if head.stdout else ''}")
        time.sleep(0.5)
    try:
        yield address
    finally:
        head.send_signal(signal.SIGINT)  # `ray start --block` stops its processes on Ctrl-C, in a second or two
        try:
            head.wait(timeout=30)
        except subprocess.TimeoutExpired:
            head.kill()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(head.pid, signal.SIGKILL)  # any worker left behind


def _map(tmp_path: Path, env: dict[str, str], name: str, *args: str) -> dict:
    out = tmp_path / f"{name}.yaml"
    cmd = objslam_cmd("map", str(BAGS / "small"), "--out", str(out), "--samples", "300", "--burn-in", "100", *args)
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=400, env=env)
    assert done.returncode == 0, done.stderr
    content = yaml.safe_load(out.read_text())
    for timing in ("timings_s", "wall_time_s"):
        content["diagnostics"].pop(timing)
    return {"content": content, "stdout": done.stdout, "stderr": done.stderr}


def test_two_chains_on_a_ray_cluster_give_the_map_of_one_process(ray_cluster, ray_env, tmp_path):
    inprocess = tmp_path / "inprocess.yaml"
    inprocess.write_text(yaml.safe_dump({"mapper": {"ros__parameters": {"parallel": {"backend": "inprocess"}}}}))
    here = _map(tmp_path, ray_env, "here", "--chains", "2", "--params", str(inprocess))
    there = _map(tmp_path, ray_env, "there", "--chains", "2", "--ray", ray_cluster)
    assert there["content"] == here["content"]
    # Without --ray, a local Ray of its own, though `ray start` left a cluster on this machine
    # (which ray.init() alone would join, refusing our CPU count).
    local = _map(tmp_path, ray_env, "local", "--chains", "2")
    assert local["content"] == here["content"]
    assert [run["start"] for run in there["content"]["diagnostics"]["chain_runs"]] == ["heuristic", "singletons"]
    converged = there["content"]["diagnostics"]["convergence"]["converged"]
    assert f"chains: 2, converged: {'yes' if converged else 'no'} (R-hat max" in there["stdout"]
    for obj in there["content"]["objects"]:  # each object's P(ID|Z) by chain, beside the pooled one
        shown = " ".join(f"{p:.2f}" for p in obj["existence_probability_by_chain"])
        assert f"P {obj['existence_probability']:.2f} [{shown}]" in there["stdout"]
    assert "sampling" in there["stderr"]  # progress while the chains ran on the cluster


def test_a_cluster_that_wants_a_token_says_how_to_give_it(ray_cluster, ray_env, tmp_path):
    # Ray retries a refused token 20 times a second apart; 3 say the same.
    env = {k: v for k, v in ray_env.items() if not k.startswith("RAY_AUTH")} | {"RAY_NUM_REDIS_GET_RETRIES": "3"}
    cmd = objslam_cmd("map", str(BAGS / "small"), "--out", str(tmp_path / "m.yaml"), "--chains", "2")
    done = subprocess.run([*cmd, "--ray", ray_cluster], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"cannot start or reach the Ray cluster at {ray_cluster}" in done.stderr
    assert "set RAY_AUTH_MODE=token" in done.stderr
    assert "detecting" not in done.stderr  # refused before the bag's images were read
    assert not (tmp_path / "m.yaml").exists()


def test_an_unreachable_cluster_is_one_clear_line(tmp_path):
    cmd = objslam_cmd("map", str(BAGS / "small"), "--out", str(tmp_path / "m.yaml"), "--chains", "2")
    done = subprocess.run([*cmd, "--ray", f"127.0.0.1:{_free_port()}"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert "cannot reach the Ray cluster at 127.0.0.1:" in done.stderr and "ray start --head" in done.stderr
    assert "detecting" not in done.stderr
    assert not (tmp_path / "m.yaml").exists()
