"""Run independent jobs over the machine's cores (a process pool) or a Ray cluster, in order,
keeping each finished job (a chunk) so that an interrupted sweep can go on where it stopped."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, TypeVar

from tqdm.auto import tqdm

from benchmarks.output import ChunkStore

T = TypeVar("T")
R = TypeVar("R")


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def run_sweep(
    fn: Callable[[T], R],
    jobs: Sequence[T],
    workers: int | None = None,
    ray_address: str | None | bool = False,
    desc: str = "runs",
    store: ChunkStore | None = None,
) -> list[R]:
    """``[fn(job) for job in jobs]``, spread over processes (or Ray), with a progress bar.

    ``ray_address``: False for the process pool; None or "" for a local Ray instance; an address
    ("auto", "ray://host:port") for a cluster. Results come back in the order of ``jobs``, so a
    sweep gives the same table wherever it ran (each job carries its own seed). ``store``
    (:class:`benchmarks.output.ChunkStore`): each result is kept there as it finishes, under
    ``desc`` and the job's index, and a job found there is not run again (``--resume``).
    """
    keys = [f"{desc}/{i}" for i in range(len(jobs))]
    results: dict[int, Any] = {}
    if store is not None:
        results = {i: store.get(k) for i, k in enumerate(keys) if k in store}
    todo = [i for i in range(len(jobs)) if i not in results]

    def done(i: int, value: Any) -> None:
        results[i] = value
        if store is not None:
            store.put(keys[i], value)

    if ray_address is not False and todo:
        _run_ray(fn, jobs, todo, ray_address or None, desc, done)
    else:
        workers = default_workers() if workers is None else workers
        with tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc=desc, unit="run") as bar:
            if workers <= 1 or len(todo) <= 1:
                for i in todo:
                    done(i, fn(jobs[i]))
                    bar.update(1)
            else:
                with ProcessPoolExecutor(max_workers=workers) as pool:
                    pending = {pool.submit(fn, jobs[i]): i for i in todo}
                    try:
                        while pending:
                            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                            for future in finished:
                                done(pending.pop(future), future.result())
                                bar.update(1)
                    except BaseException:
                        for future in pending:  # what has not started does not start
                            future.cancel()
                        raise
    return [results[i] for i in range(len(jobs))]


def _run_ray(
    fn: Callable[[T], R],
    jobs: Sequence[T],
    todo: list[int],
    address: str | None,
    desc: str,
    done: Callable[[int, Any], None],
) -> None:
    try:
        import ray
    except ImportError as err:  # pragma: no cover - depends on the optional extra
        raise RuntimeError("--ray needs the optional extra: pip install 'riskcrossing[ray]'") from err
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(fn)
        refs = {remote.remote(jobs[i]): i for i in todo}
        pending = list(refs)
        with tqdm(total=len(refs), desc=f"{desc} (ray)", unit="run") as bar:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                done(refs[ready[0]], ray.get(ready[0]))
                bar.update(1)
    finally:
        if started:
            ray.shutdown()
