"""Where shards are solved: ``serial`` (this process), ``processes`` (worker processes on this
machine) or ``dask`` (a ``LocalCluster`` by default, or a running scheduler's address to spread
over machines). Each yields solved shards as they finish.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
import threading
import time

from fem.placements import Plan
from fem.worker import payload, solve_shard


class WorkerDied(ChildProcessError):
    """A worker process ended without a word (killed by the system, most often for memory)."""

    def __init__(self, shards: list[int]):
        self.shards = shards
        super().__init__(
            f"a worker process died while solving shard(s) {', '.join(map(str, shards))} "
            "(killed by the system: out of memory? see dmesg); the finished shards and the "
            "kept progress stay, the same command resumes from them, and fewer --workers "
            "need less memory"
        )


def _watch_parent(parent: int) -> None:
    """Worker initialiser: leave when the generating process is gone (killed), rather than
    finish orphaned shards that nobody will write.
    """

    def watch():
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _drain(queue, tell) -> None:
    """Pass on to ``tell`` every count the workers have put in ``queue``."""
    if queue is None:
        return
    n = 0
    while not queue.empty():
        n += queue.get_nowait()
    if n:
        tell(n)


def run(p: Plan, todo: list[int], par: dict, threads: int, tell=None, keep=None):
    """Yield solved shards as they finish, from the chosen backend. ``tell(n)``: called in this
    process as planned samples end inside the shards (``serial`` and ``processes``; ``dask``
    reports none: its shards' samples are counted as each shard arrives). ``keep(k)``: the file
    in which shard ``k``'s progress is kept as it goes (``serial`` and ``processes``, whose
    workers share this disk; a stopped shard takes it up again), or ``None``.
    """
    kept = keep if keep is not None else (lambda k: None)
    if not todo:
        return
    if par["backend"] == "serial" or (par["backend"] == "processes" and par["workers"] == 1):
        for k in todo:
            yield solve_shard(payload(p, k, None, tell, kept(k)))
        return
    if par["backend"] == "processes":
        ctx = mp.get_context("spawn")
        ex = cf.ProcessPoolExecutor(
            par["workers"], mp_context=ctx, initializer=_watch_parent, initargs=(os.getpid(),)
        )
        manager = ctx.Manager() if tell is not None else None  # carries the workers' ticks
        queue = manager.Queue() if manager is not None else None
        shard = {ex.submit(solve_shard, payload(p, k, threads, queue, kept(k))): k for k in todo}
        solving: list[int] = []
        try:
            pending = set(shard)
            while pending:
                finished, pending = cf.wait(pending, timeout=0.5, return_when=cf.FIRST_COMPLETED)
                _drain(queue, tell)
                solving = sorted(shard[f] for f in pending if f.running()) or solving
                for f in finished:
                    try:
                        yield f.result()
                    except cf.process.BrokenProcessPool:
                        raise WorkerDied(solving or sorted(shard[f] for f in pending)) from None
        except BaseException:  # stopped (Ctrl-C, SIGTERM) or failed: the workers go at once
            for proc in list((getattr(ex, "_processes", None) or {}).values()):
                proc.terminate()
            ex.shutdown(wait=False, cancel_futures=True)
            raise
        finally:
            if manager is not None:
                manager.shutdown()
        ex.shutdown()
        return
    from dask.distributed import (
        Client,
        LocalCluster,
        as_completed,
    )  # deferred: the distributed backend only

    cluster = None
    if par["scheduler"]:
        client = Client(par["scheduler"])
    else:
        cluster = LocalCluster(
            n_workers=par["workers"], threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    try:
        futs = [client.submit(solve_shard, payload(p, k, threads), pure=False) for k in todo]
        for f in as_completed(futs):
            yield f.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
