"""Runs spread over processes or machines through any :class:`concurrent.futures.Executor`.

The runs of a run set, the perturbed runs of a finite-difference gradient and the failure runs of a strength
calibration are independent: given an ``executor``, jaxbpm submits them as separate tasks and collects them as they
finish. Any executor works:

* :class:`concurrent.futures.ProcessPoolExecutor` (use the ``"spawn"`` start method: a process forked from one that
  has started JAX can hang) on one machine;
* Dask distributed, ``Client(...).get_executor()`` (the ``jaxbpm[dask]`` extra): a ``LocalCluster`` on a
  workstation, or ``dask-jobqueue``'s ``SLURMCluster`` / ``PBSCluster`` on a cluster -- the same code;
* :class:`concurrent.futures.ThreadPoolExecutor` (little gain: one run already uses every core of its process).

What a task carries: the sample, the scene, the solver name, its options and one parameter set, pickled (a sample of
10k particles is ~2 MB); no compiled program. Each worker compiles once (or loads the programs from JAX's persistent
compilation cache: when the submitting process has the cache on -- :func:`jaxbpm.enable_compilation_cache` --
every worker turns it on in the same directory, so the workers of one machine, or of a cluster with a shared file
system, compile each program once between them). Each worker also takes the submitting process's float64 setting
(``jax_enable_x64``), so a run gives the same numbers wherever it runs.

A task whose worker died (the process killed, out of memory, a lost connection) is submitted again, up to
``retries`` times; an error of the run itself (a solve that did not converge, bad input) is not retried and is raised
in the submitting process. Dask also reschedules the tasks of a lost worker itself. With a file (``run_set(...,
path=)``), every finished run is stored as it arrives, so a run set interrupted or stopped by a failure resumes
where it stopped.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["check_executor", "check_retries", "worker_settings", "Task", "run_tasks", "WorkerLost"]


class WorkerLost(RuntimeError):
    """A task's worker died more often than ``retries`` allows, or the executor itself broke."""


def check_executor(executor):
    """An executor checked.

    Args:
      executor: ``None``, or an object with the :class:`concurrent.futures.Executor` interface (``submit``).

    Returns:
      ``executor``.

    Raises:
      TypeError: anything else (the message says what to pass).
    """
    if executor is None or (callable(getattr(executor, "submit", None)) and not isinstance(executor, type)):
        return executor
    raise TypeError(f"executor must be a concurrent.futures.Executor (e.g. ProcessPoolExecutor, or a Dask "
                    f"Client(...).get_executor()), got {executor!r}")


def check_retries(retries) -> int:
    """A retry count checked.

    Args:
      retries: a whole number >= 0.

    Returns:
      ``retries`` as an int.

    Raises:
      ValueError: anything else.
    """
    if isinstance(retries, bool) or not isinstance(retries, (int, np.integer)) or retries < 0:
        raise ValueError(f"retries must be a whole number >= 0, got {retries!r}")
    return int(retries)


def worker_settings() -> dict:
    """The JAX settings a worker takes from the submitting process.

    Returns:
      ``{"x64": bool, "cache_dir": str or None}``: float64 on or off, and the compilation cache directory where the
      cache is on.
    """
    import jax

    cache = getattr(jax.config, "jax_compilation_cache_dir", None)
    enabled = getattr(jax.config, "jax_enable_compilation_cache", True)
    return {"x64": bool(jax.config.jax_enable_x64), "cache_dir": str(cache) if (cache and enabled) else None}


_APPLIED: dict = {}


def _apply(settings: dict) -> None:
    """Make this (worker) process's JAX settings those of the submitting process (once per setting)."""
    if _APPLIED == settings:
        return
    import jax

    if bool(jax.config.jax_enable_x64) != settings["x64"]:
        jax.config.update("jax_enable_x64", settings["x64"])
    if settings["cache_dir"] and getattr(jax.config, "jax_compilation_cache_dir", None) != settings["cache_dir"]:
        from jaxbpm._cache import enable_compilation_cache

        try:
            enable_compilation_cache(settings["cache_dir"])
        except OSError:  # another machine without that directory: this worker compiles for itself
            pass
    _APPLIED.clear()
    _APPLIED.update(settings)


@dataclasses.dataclass(frozen=True)
class Task:
    """One independent run: ``fn(*args)`` in a worker with the submitting process's JAX ``settings``; ``fn`` must be
    picklable (a module-level function)."""

    fn: Callable
    args: tuple
    settings: dict


def _run(task: Task):
    _apply(task.settings)
    return task.fn(*task.args)


# errors that say the worker, not the run, failed: the task is submitted again
_LOST = ("KilledWorker", "CommClosedError", "StreamClosedError", "WorkerLost", "CancelledError", "FutureCancelledError")


def _worker_failed(exc: BaseException) -> bool:
    if isinstance(exc, (cf.CancelledError, EOFError, ConnectionError)):
        return True
    return any(type(exc).__name__ == name for name in _LOST)


def run_tasks(executor, tasks: Sequence[Task], *, on_result: Callable[[int, Any], None] | None = None,
              retries: int = 2, progress=None) -> list:
    """Run ``tasks`` on ``executor`` and return their results in order.

    An error of a task is raised here once the tasks already running have finished and been passed to ``on_result``;
    the tasks not yet started are cancelled.

    Args:
      executor: a :class:`concurrent.futures.Executor`.
      tasks: the :class:`Task` s.
      on_result: called ``(index, result)`` in the submitting process as each task finishes (in completion order),
        e.g. to store it.
      retries: how often a task whose worker died is submitted again.
      progress: a bar with ``update(k)`` (:mod:`jaxbpm.progress`) or ``None``.

    Returns:
      The tasks' results, in the order of ``tasks``.

    Raises:
      WorkerLost: a task's worker died more often than ``retries`` allows, or the executor broke.
      KeyboardInterrupt: interrupted (the tasks not yet started are cancelled).
      Exception: the first error a task raised.
    """
    from jaxbpm._interrupt import check, guard

    retries = check_retries(retries)
    results: list = [None] * len(tasks)
    tries = [0] * len(tasks)
    error: BaseException | None = None
    with guard():
        pending = {_submit(executor, tasks[i]): i for i in range(len(tasks))}
        while pending:
            try:
                done, _ = cf.wait(list(pending), timeout=0.5, return_when=cf.FIRST_COMPLETED)
                check()
            except KeyboardInterrupt:
                # Ctrl-C: cancel what has not started and keep what finishes; a second Ctrl-C stops waiting
                if isinstance(error, KeyboardInterrupt):
                    raise
                error, done = KeyboardInterrupt(), set()
                for f in pending:
                    f.cancel()
            for fut in done:
                i = pending.pop(fut)
                try:
                    value = fut.result()
                except BaseException as exc:  # noqa: BLE001 - sorted out just below
                    if isinstance(exc, cf.BrokenExecutor):
                        error = error or WorkerLost(f"the executor broke while running task {i} ({exc}); runs "
                                                    "already finished are kept where a file stores them")
                    elif _worker_failed(exc) and tries[i] < retries and error is None:
                        tries[i] += 1
                        pending[_submit(executor, tasks[i])] = i
                    elif _worker_failed(exc):
                        error = error or WorkerLost(f"task {i}: its worker died {tries[i] + 1} times ({exc!r})")
                    else:
                        error = error or exc
                    if error is not None:
                        for f in pending:
                            f.cancel()
                    continue
                results[i] = value
                if on_result is not None:
                    on_result(i, value)
                if progress is not None:
                    progress.update(1)
            if error is not None:  # wait only for what is already running
                pending = {f: i for f, i in pending.items() if not f.cancelled()}
    if error is not None:
        raise error
    return results


def _submit(executor, task: Task):
    try:
        return executor.submit(_run, task)
    except RuntimeError as exc:  # shut down, or broken
        raise WorkerLost(f"the executor accepts no more tasks ({exc})") from exc
