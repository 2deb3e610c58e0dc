"""Run independent jobs over the machine's cores (a process pool) or a Ray cluster, in order."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from tqdm.auto import tqdm

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
) -> list[R]:
    """``[fn(job) for job in jobs]``, spread over processes (or Ray), with a progress bar.

    ``ray_address``: False for the process pool; None or "" for a local Ray instance; an address
    ("auto", "ray://host:port") for a cluster. Results come back in the order of ``jobs``, so a
    sweep gives the same table wherever it ran (each job carries its own seed).
    """
    if ray_address is not False:
        return _run_ray(fn, jobs, ray_address or None, desc)
    workers = default_workers() if workers is None else workers
    if workers <= 1 or len(jobs) <= 1:
        return [fn(job) for job in tqdm(jobs, desc=desc, unit="run")]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(fn, job) for job in jobs]
        return [f.result() for f in tqdm(futures, desc=desc, unit="run")]


def _run_ray(fn: Callable[[T], R], jobs: Sequence[T], address: str | None, desc: str) -> list[R]:
    try:
        import ray
    except ImportError as err:  # pragma: no cover - depends on the optional extra
        raise RuntimeError("--ray needs the optional extra: pip install 'riskcrossing[ray]'") from err
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(fn)
        refs = [remote.remote(job) for job in jobs]
        results: dict[Any, R] = {}
        pending = list(refs)
        with tqdm(total=len(refs), desc=f"{desc} (ray)", unit="run") as bar:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                results[done[0]] = ray.get(done[0])
                bar.update(1)
        return [results[r] for r in refs]
    finally:
        if started:
            ray.shutdown()
