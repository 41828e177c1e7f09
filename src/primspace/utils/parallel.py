"""One interface for running independent jobs: in-process, on a local process pool, or on Ray.

A job is ``fn(*args)`` for one item of a list: a shard of data generation, one training
run of an experiment grid. Results come back tagged with the item's index, so callers
never depend on completion order, and a job's seed must derive from its item alone
(never from the worker it lands on): then every backend gives identical results.

A failed job does not stop the others: its :class:`JobOutcome` carries the error text
and the caller decides (data generation stops; an experiment grid reports and goes on).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

from primspace.utils.errors import UserError, first_line
from primspace.utils.progress import progress_bar

__all__ = ["JobOutcome", "run_jobs", "BACKENDS", "default_workers"]

BACKENDS = ("local", "ray")


@dataclass
class JobOutcome:
    """What one job returned, or the error it raised."""

    index: int
    value: Any = None
    error: str | None = None  # one line: "ExceptionType: message"
    traceback: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def default_workers() -> int:
    """Usable CPU cores of this process."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def run_jobs(
    fn: Callable[..., Any],
    items: Sequence[tuple],
    *,
    backend: str = "local",
    workers: int | None = 1,
    address: str | None = None,
    description: str = "jobs",
    progress: bool | None = None,
    threads_per_job: int = 1,
) -> Iterator[JobOutcome]:
    """Run ``fn(*item)`` for every item; yield a :class:`JobOutcome` per item as each ends.

    Parameters
    ----------
    fn : callable
        A module-level function (it is pickled to worker processes).
    items : sequence of tuples
        Arguments of each job.
    backend : {"local", "ray"}
        ``local``: in this process when ``workers == 1``, else a process pool.
        ``ray``: tasks on a Ray cluster (``address``), or on a local Ray instance.
    workers : int, optional
        Local processes (None: all usable cores). Ignored by ``ray``.
    address : str, optional
        Ray cluster address (``ray``: None starts a local instance).
    description : str
        Progress-bar text.
    progress : bool, optional
        Show a progress bar (default: when stderr is a terminal).
    threads_per_job : int
        Math-library threads each worker process may use.
    """
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; choose from {', '.join(BACKENDS)}")
    items = list(items)
    with progress_bar(len(items), description, enabled=progress) as advance:
        if backend == "ray":
            runner = _run_ray(fn, items, address, workers, threads_per_job)
        elif workers is not None and workers == 1 or len(items) <= 1:
            runner = (_call(fn, i, args) for i, args in enumerate(items))
        else:
            runner = _run_pool(fn, items, workers or default_workers(), threads_per_job)
        for outcome in runner:
            advance()
            yield outcome


def _call(fn: Callable, index: int, args: tuple) -> JobOutcome:
    try:
        return JobOutcome(index, fn(*args))
    except Exception as exc:  # a job's failure is data for the caller, not a crash
        return JobOutcome(index, None, f"{type(exc).__name__}: {exc}", traceback.format_exc())


def _init_worker(threads: int, parent_pid: int) -> None:
    _limit_threads(threads)
    _exit_with_parent(parent_pid)


def _exit_with_parent(parent_pid: int, interval: float = 1.0) -> None:
    """Exit this worker when the driver that started it is gone (killed with SIGKILL, say).

    A pool worker otherwise finishes its job and then waits forever on the queue of a
    dead driver, holding cores and memory. Its unfinished run resumes from its
    checkpoint when the driver is started again.
    """

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(interval)
        os._exit(1)

    threading.Thread(target=watch, name="primspace-parent-watch", daemon=True).start()


def _limit_threads(n: int) -> None:
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(n)
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(n)
    except Exception:  # pragma: no cover - threadpoolctl is a dependency
        pass


def _run_pool(fn: Callable, items: list, workers: int, threads: int) -> Iterator[JobOutcome]:
    # spawn, not fork: forking a process that holds torch/OpenMP threads or a GL context
    # can deadlock; workers import what they need.
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=min(workers, len(items)), mp_context=ctx, initializer=_init_worker, initargs=(threads, os.getpid())
    ) as pool:
        pending = {pool.submit(_call, fn, i, args): i for i, args in enumerate(items)}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    i = pending.pop(fut)
                    try:
                        yield fut.result()
                    except Exception as exc:  # the worker process itself died
                        yield JobOutcome(i, None, f"{type(exc).__name__}: {exc}", traceback.format_exc())
        finally:
            # a caller that stops early (closes this generator, e.g. on a failed job)
            # must not wait for every queued job: drop those not started yet
            pool.shutdown(wait=True, cancel_futures=True)


def _run_ray(fn: Callable, items: list, address: str | None, workers: int | None, threads: int) -> Iterator[JobOutcome]:
    """Run the jobs as Ray tasks, one CPU each; ray is imported only here.

    With ``address`` the driver joins a running cluster (``"auto"``, ``"HOST:PORT"`` or
    ``"ray://HOST:10001"``); without it a local Ray instance is started with ``workers``
    CPUs (all cores by default) and stopped at the end. primspace must be importable on
    every node (install it there, or pass a ``runtime_env`` through ``RAY_RUNTIME_ENV``).
    """
    try:
        import ray
    except ImportError:
        raise UserError("--backend ray needs Ray: pip install 'primspace[ray]'") from None
    started_here = not ray.is_initialized()
    if started_here:
        kwargs = dict(include_dashboard=False, logging_level="ERROR", log_to_driver=False)
        try:
            if address:
                ray.init(address=address, **kwargs)
            else:
                ray.init(num_cpus=workers or default_workers(), **kwargs)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise UserError(
                f"cannot start or reach Ray at {address or 'a local instance'}: {first_line(exc)}"
            ) from None
    try:
        remote_call = ray.remote(num_cpus=threads, max_retries=0)(_call_with_threads)
        pending = {remote_call.remote(fn, i, args, threads): i for i, args in enumerate(items)}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                i = pending.pop(ref)
                try:
                    yield ray.get(ref)
                except Exception as exc:  # the task's worker died (OOM, node lost)
                    yield JobOutcome(i, None, f"{type(exc).__name__}: {first_line(exc)}", traceback.format_exc())
    finally:
        for ref in pending:  # a caller that stopped early: drop the jobs still queued
            ray.cancel(ref)
        if started_here:
            ray.shutdown()


def _call_with_threads(fn: Callable, index: int, args: tuple, threads: int) -> JobOutcome:
    _limit_threads(threads)
    return _call(fn, index, args)
