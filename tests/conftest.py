"""Fixtures shared by every test package.

ROS tests run nodes and ``objslam`` verbs as subprocesses over a real graph. Each test
session (each pytest-xdist worker) gets its own ROS_DOMAIN_ID and localhost-only discovery
so parallel runs (and other users of the machine) never see each other's topics.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import zlib
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import settings

# In CI the property tests draw the same examples every run, so a red CI is the change's
# fault, not a new draw's; on a developer's machine they keep exploring.
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / "bags"


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO


@pytest.fixture(scope="session")
def ros_env() -> dict[str, str]:
    """Environment for ROS subprocesses: an isolated domain on localhost."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(ros_domain_id())
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def ros_domain_id() -> int:
    """A domain in 100-199 of this session's own; under pytest-xdist (``-n N``) the workers
    of one run take neighbouring domains, so no two of them ever share one."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID") or str(os.getpid())
    return 100 + (zlib.crc32(run.encode()) % (100 // workers)) * workers + worker


def objslam_cmd(*args: str) -> list[str]:
    """Command line running the objslam CLI with this interpreter."""
    return [sys.executable, "-m", "objslam_tools.cli", *args]


class Processes:
    """Subprocesses started by a test; all are stopped at teardown."""

    def __init__(self, env: dict[str, str]):
        self.env = env
        self.started: list[subprocess.Popen] = []

    def start(self, args: list[str], **kwargs) -> subprocess.Popen:
        proc = subprocess.Popen(args, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)
        self.started.append(proc)
        return proc

    def run(self, args: list[str], timeout: float = 60.0) -> subprocess.CompletedProcess:
        return subprocess.run(args, env=self.env, capture_output=True, text=True, timeout=timeout)

    def stop_all(self) -> None:
        for proc in self.started:
            if proc.poll() is None:
                proc.terminate()
        deadline = time.monotonic() + 10
        for proc in self.started:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture
def processes(ros_env: dict[str, str]) -> Iterator[Processes]:
    procs = Processes(ros_env)
    try:
        yield procs
    finally:
        procs.stop_all()


@pytest.fixture(scope="session")
def damaged_small_bag(tmp_path_factory) -> Path:
    """bags/small with three bad odometry messages and two unusable frames (tests/damaged_bag.py)."""
    from tests.damaged_bag import damaged_small

    return damaged_small(BAGS, tmp_path_factory.mktemp("damaged") / "small_damaged")
