"""The shared fixtures' own promises (tests/conftest.py)."""

from __future__ import annotations

import pytest

from tests.conftest import ros_domain_id


@pytest.mark.parametrize("workers", [1, 2, 3, 4])
@pytest.mark.parametrize("run", ["a1b2c3", "ffff0000", "9"])
def test_the_workers_of_one_run_take_distinct_ros_domains_in_100_to_199(monkeypatch, workers, run):
    monkeypatch.setenv("PYTEST_XDIST_TESTRUNUID", run)
    monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", str(workers))
    domains = []
    for worker in range(workers):
        monkeypatch.setenv("PYTEST_XDIST_WORKER", f"gw{worker}")
        domains.append(ros_domain_id())
    assert len(set(domains)) == workers
    assert all(100 <= d <= 199 for d in domains)
