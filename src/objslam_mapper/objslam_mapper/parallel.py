"""Chains in parallel as Ray tasks: on a local Ray started on demand, or on an existing cluster.

:class:`RayRunner` runs each chain task (:func:`objslam_mapper.inference.chains.run_chain_task`)
as a Ray task, the problem and the tracklets put into Ray's object store once. A chain is a
pure function of its task, so the map is the one :class:`~objslam_mapper.inference.chains.InProcess`
builds, wherever the tasks ran. Which cluster: the ``--ray`` address a command was given,
else ``parallel.ray_address``, else ``RAY_ADDRESS``, else a local Ray with
``parallel.workers`` CPUs (every core by default), started on first use and shut down by
:meth:`RayRunner.close`: always one of its own, never a ``ray start`` cluster that was not
named. The tasks pin BLAS to one thread, as this process does (:mod:`objslam_common`): two
chains on two cores must not fight over four threads, and the same sums in the same order
give the same map.

Progress: each task reports its steps to a small Ray actor, which this process polls.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from objslam_common.process import BLAS_THREAD_VARIABLES
from objslam_mapper.config import ParallelConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.inference.chains import ChainOutcome, ChainRunner, ChainTask, InProcess, run_chain_task

logger = logging.getLogger(__name__)

_THREADS = dict.fromkeys(BLAS_THREAD_VARIABLES, "1")
_POLL_S = 0.5


class ParallelError(MapperError, RuntimeError):
    """Ray is missing, or the cluster cannot be reached."""


def ray_address(config: ParallelConfig, override: str | None = None) -> str | None:
    """The cluster to use: the override, the parameter, ``RAY_ADDRESS``; None for a local Ray."""
    return override or config.ray_address or os.environ.get("RAY_ADDRESS") or None


class RayRunner:
    """Chain tasks as Ray tasks (module docstring); one runner may serve many builds."""

    def __init__(self, address: str | None = None, workers: int = 0) -> None:
        self.address = address
        self.workers = workers or os.cpu_count() or 1
        self._started_ray = False
        self._remote: Any = None
        self._reporter: Any = None
        self._warming: list[Any] = []

    def ray(self) -> Any:
        """The ``ray`` module, connected (a local Ray started on first use)."""
        # Ray's crash handler would take SIGTERM from the process that hosts us (a node that
        # cancels its build and answers on SIGTERM, then ends) and abort it. Read at import.
        os.environ.setdefault("RAY_DISABLE_FAILURE_SIGNAL_HANDLER", "1")
        try:
            import ray
        except ImportError as exc:
            raise ParallelError("Ray is not installed: run `make setup`, or set parallel.backend: inprocess") from exc
        if not ray.is_initialized():
            started = time.monotonic()
            if self.address:
                _check_reachable(self.address)
            try:
                if self.address:
                    ray.init(address=self.address, logging_level=logging.ERROR, log_to_driver=False)
                else:
                    # "local": a Ray of our own even where `ray start` left a cluster on this
                    # machine, which a bare ray.init() would join (and refuse num_cpus).
                    ray.init(
                        address="local",
                        num_cpus=self.workers,
                        include_dashboard=False,
                        logging_level=logging.ERROR,
                        log_to_driver=False,
                    )
                    self._started_ray = True
            except (ConnectionError, RuntimeError, ValueError) as exc:
                where = f"the Ray cluster at {self.address}" if self.address else "a local Ray"
                hint = ""
                if self.address and "RAY_AUTH_MODE" not in os.environ:
                    hint = f" ({_AUTH_HINT})"
                raise ParallelError(f"cannot start or reach {where}: {str(exc).splitlines()[0]}{hint}") from exc
            logger.info(
                "Ray %s in %.1f s: %s CPUs",
                f"cluster {self.address}" if self.address else "started locally",
                time.monotonic() - started,
                int(ray.cluster_resources().get("CPU", 0)),
            )
        if self._remote is None:
            # Warm the workers up while this process does other work: a fresh worker takes a
            # second to import the mapper, which the first chains would otherwise pay.
            warm = ray.remote(num_cpus=1)(_import_mapper)
            self._warming = [warm.remote() for _ in range(int(ray.cluster_resources().get("CPU", 1)))]
            remote = ray.remote(num_cpus=1)(_run_remote)
            # A local Ray's workers inherit this process's environment, BLAS pinned already; a
            # cluster's get it per task (which costs a worker start of its own).
            self._remote = remote.options(runtime_env={"env_vars": _THREADS}) if self.address else remote
        return ray

    def run(self, tasks: Sequence[ChainTask], progress: Callable[[int, int], None] | None = None) -> list[ChainOutcome]:
        if not tasks:
            return []
        ray = self.ray()
        if self._reporter is None:  # one actor for every run: starting one costs a worker process
            self._reporter = ray.remote(num_cpus=0)(_Steps).remote()
        reporter = self._reporter
        ray.get(reporter.reset.remote(len(tasks)))
        shared: dict[int, Any] = {}  # one object-store copy of each problem and tracklet set

        def put(value: Any) -> Any:
            if id(value) not in shared:
                shared[id(value)] = ray.put(value)
            return shared[id(value)]

        # Longest first (measurements x steps): Ray starts tasks in the order they come, and a
        # long chain started last would run alone at the end while the other cores idle.
        order = sorted(range(len(tasks)), key=lambda k: -tasks[k].problem.measurement_count * tasks[k].config.samples)
        submitted = {
            k: self._remote.remote(
                put(tasks[k].problem), put(tasks[k].tracklets), tasks[k].config, tasks[k].spec, reporter, k
            )
            for k in order
        }
        futures = [submitted[k] for k in range(len(tasks))]
        total = sum(task.config.samples for task in tasks)
        pending = list(futures)
        try:
            while pending:
                _, pending = ray.wait(pending, num_returns=len(pending), timeout=_POLL_S)
                if progress is not None:
                    progress(min(int(ray.get(reporter.done.remote())), total), total)
        except BaseException:
            # The caller gave up (its progress callback raised to cancel): free the workers.
            for future in pending:
                ray.cancel(future, force=True)
            raise
        return list(ray.get(futures))

    def close(self) -> None:
        """Shut the local Ray down if this runner started it."""
        if self._started_ray:
            import ray

            ray.shutdown()
            self._started_ray = False
            self._remote = self._reporter = None


# Ray (2.52 on) does not send a token to a cluster named by address unless told to, while
# `ray start` turns token authentication on by default: the usual reason a reachable
# cluster refuses us.
_AUTH_HINT = (
    "a cluster started by `ray start` wants its token: set RAY_AUTH_MODE=token, with the token in "
    "RAY_AUTH_TOKEN or ~/.ray/auth_token"
)
_REACH_TIMEOUT_S = 5.0


def _check_reachable(address: str) -> None:
    """Fail at once when nothing listens at ``host:port``: ``ray.init`` would retry for minutes.
    ``auto`` and Ray Client addresses (``ray://``) are left to Ray."""
    host, _, port = address.rpartition(":")
    if address == "auto" or "://" in address or not host or not port.isdigit():
        return
    try:
        socket.create_connection((host, int(port)), timeout=_REACH_TIMEOUT_S).close()
    except OSError as exc:
        raise ParallelError(
            f"cannot reach the Ray cluster at {address}: {exc.strerror or exc} (is `ray start --head` running there?)"
        ) from exc


class _Steps:
    """Steps done by each chain (a Ray actor)."""

    def __init__(self) -> None:
        self.steps: list[int] = []

    def reset(self, chains: int) -> None:
        self.steps = [0] * chains

    def report(self, chain: int, done: int) -> None:
        self.steps[chain] = done

    def done(self) -> int:
        return sum(self.steps)


def _import_mapper() -> None:
    import objslam_mapper.inference.chains  # noqa: F401  (the import is the point)


def _run_remote(problem: Any, tracklets: Any, config: Any, spec: Any, reporter: Any, slot: int) -> ChainOutcome:
    def report(done: int, _total: int) -> None:
        reporter.report.remote(slot, done)  # the task's place in the run: a batch has many chains 0

    return run_chain_task(ChainTask(problem, tracklets, config, spec), report)


def chain_runner(config: ParallelConfig, chains: int, address: str | None = None) -> ChainRunner:
    """The runner a build uses: in this process for one chain or ``backend: inprocess``, else Ray."""
    if chains <= 1 or config.backend == "inprocess":
        return InProcess()
    return RayRunner(ray_address(config, address), config.workers)


@contextmanager
def running_chains(config: ParallelConfig, chains: int, address: str | None = None) -> Iterator[ChainRunner]:
    """:func:`chain_runner`'s runner, closed (a local Ray it started shut down) when the block ends."""
    runner = chain_runner(config, chains, address)
    try:
        yield runner
    finally:
        if isinstance(runner, RayRunner):
            runner.close()
