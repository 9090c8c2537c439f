"""Handing the report's figures to the drawing processes.

A drawing process reuses a grid of panels for every figure of the same layout (reports.canvas.panels):
the first figure of a layout costs about a third more (axes and tick objects created, fonts loaded).
Handed out one by one, every layout was first drawn in every process. So the figures are split ahead
into one list per process, of about equal estimated cost, the figures of one layout kept together
(largest groups first, each to the least loaded process; a group that would overfill a process is
split). Each process draws its list and sends every figure as it is done through a queue, so progress
is still reported figure by figure.
"""
from __future__ import annotations

import os
import queue

__all__ = ["split", "draw_in_processes"]


def split(tasks, jobs: int, group, cost) -> list:
    """``tasks`` in ``jobs`` lists: the tasks of one ``group(task)`` together where the balance allows,
    the estimated ``cost(task)`` of the lists about equal; each list costliest first."""
    groups: dict = {}
    for t in tasks:
        groups.setdefault(group(t), []).append(t)
    pending = [sorted(g, key=lambda t: -cost(t)) for g in groups.values()]
    target = sum(cost(t) for t in tasks) / jobs
    bins, load = [[] for _ in range(jobs)], [0.0] * jobs
    while pending:
        pending.sort(key=lambda g: -sum(cost(t) for t in g))
        g = pending.pop(0)
        i = min(range(jobs), key=load.__getitem__)
        room = target * 1.05 - load[i]
        take = []
        for t in g:
            if take and sum(cost(x) for x in take) + cost(t) > room:
                break
            take.append(t)
        if len(take) < len(g):
            pending.append(g[len(take):])
        bins[i] += take
        load[i] += sum(cost(t) for t in take)
    return [sorted(b, key=lambda t: -cost(t)) for b in bins if b]


_QUEUE: dict = {}


def _init(parent_pid, q, worker_init):
    _QUEUE["q"] = q
    if worker_init is not None:
        worker_init(parent_pid)


def _draw_list(draw, tasks) -> int:
    for t in tasks:
        _QUEUE["q"].put(draw(t))
    return len(tasks)


def draw_in_processes(draw, lists, done, ctx=None, worker_init=None) -> None:
    """Run ``draw(task)`` for every task of each list of ``lists`` in its own process; ``done(i, result)``
    is called in this process as each result arrives (i = 1, 2, ...). A process's exception is raised
    here. ``draw`` and ``worker_init(parent_pid)`` must be importable module functions."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    q = (ctx or mp).Queue()
    n_tasks = sum(len(b) for b in lists)
    with ProcessPoolExecutor(max_workers=len(lists), mp_context=ctx, initializer=_init,
                             initargs=(os.getpid(), q, worker_init)) as pool:
        futures = [pool.submit(_draw_list, draw, b) for b in lists]
        i = 0
        while i < n_tasks:
            try:
                item = q.get(timeout=0.25)
            except queue.Empty:
                for f in futures:
                    if f.done() and f.exception() is not None:
                        raise f.exception() from None   # the drawing's own error, not the empty queue
                continue
            i += 1
            done(i, item)
        for f in futures:
            f.result()
