"""reports.schedule: the figures split ahead between the drawing processes, one layout's figures kept
together while the processes' estimated work stays about equal; every figure drawn exactly once, and a
drawing process's exception reaches the caller."""
import pytest

from reports.schedule import draw_in_processes, split


def test_a_split_keeps_layouts_together_balances_the_work_and_loses_no_figure():
    tasks = [(g, k) for g, n in (("ladder", 22), ("time", 11), ("time-log", 20), ("work", 11)) for k in range(n)]
    cost = {"ladder": 3.0, "time": 4.0, "time-log": 2.0, "work": 1.0}
    lists = split(tasks, 2, group=lambda t: t[0], cost=lambda t: cost[t[0]])
    assert sorted(t for b in lists for t in b) == sorted(tasks)
    loads = [sum(cost[t[0]] for t in b) for b in lists]
    assert max(loads) <= 1.1 * sum(loads) / 2
    # a layout lands in one process unless it had to be split to keep the balance: at most one is split
    split_groups = [g for g in cost if all(any(t[0] == g for t in b) for b in lists)]
    assert len(split_groups) <= 1


def test_one_process_gets_everything_costliest_first():
    [only] = split([("a", 1), ("b", 2), ("a", 3)], 1, group=lambda t: t[0], cost=lambda t: t[1])
    assert only == [("a", 3), ("b", 2), ("a", 1)]


def _square(x):
    return x * x


def _fail_on_three(x):
    if x == 3:
        raise ValueError("planted failure on 3")
    return x


def test_every_result_arrives_once_and_a_workers_exception_is_raised_here():
    got = []
    draw_in_processes(_square, [[1, 2, 3], [4, 5]], lambda i, r: got.append((i, r)))
    assert [i for i, _ in got] == [1, 2, 3, 4, 5] and sorted(r for _, r in got) == [1, 4, 9, 16, 25]
    with pytest.raises(ValueError, match="planted failure on 3"):
        draw_in_processes(_fail_on_three, [[1, 2, 3, 4]], lambda i, r: None)
