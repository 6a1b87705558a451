"""parallel.run_tasks: in-process and local processes; failing and crashing tasks are reported."""

from __future__ import annotations

import pytest

from aveas_format.parallel import run_tasks

from helpers_parallel import crash_on_two, fail_on_three, square


@pytest.mark.parametrize("workers", [1, 2])
def test_all_results_come_back(workers):
    res = sorted(run_tasks(square, range(10), workers=workers), key=lambda r: r.index)
    assert [r.value for r in res] == [i * i for i in range(10)]
    assert all(r.ok for r in res)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_task_does_not_stop_the_others(workers):
    res = {r.item: r for r in run_tasks(fail_on_three, range(6), workers=workers)}
    assert res[3].error == "ValueError: three is not allowed" and "Traceback" in res[3].traceback
    assert [res[i].value for i in (0, 1, 2, 4, 5)] == [0, 1, 2, 4, 5]


def test_a_task_that_kills_its_worker_is_reported_and_the_rest_complete():
    res = {r.item: r for r in run_tasks(crash_on_two, range(8), workers=2)}
    assert set(res) == set(range(8))
    assert "worker process died" in res[2].error
    assert all(res[i].value == i + 100 for i in range(8) if i != 2)


@pytest.mark.parametrize("workers", [1, 2])
def test_map_ordered_keeps_the_input_order_of_a_lazy_iterable(workers):
    from aveas_format.parallel import map_ordered

    consumed = []

    def items():
        for i in range(12):
            consumed.append(i)
            yield i

    out = []
    for item, value in map_ordered(square, items(), workers=workers, ahead=3):
        assert len(consumed) <= item + 1 + 3  # at most `ahead` items in flight past this one
        out.append((item, value))
    assert out == [(i, i * i) for i in range(12)]


@pytest.mark.parametrize("workers", [1, 2])
def test_map_ordered_raises_a_task_error_at_its_position(workers):
    from aveas_format.parallel import map_ordered

    got = []
    with pytest.raises(ValueError, match="three is not allowed"):
        for item, value in map_ordered(fail_on_three, range(8), workers=workers):
            got.append(value)
    assert got == [0, 1, 2]


def test_background_runs_in_a_thread_of_its_own_and_hands_back_the_result_or_the_error():
    import threading

    from aveas_format.parallel import background

    fut = background(lambda a, b: (threading.current_thread().name, a + b), 2, 3, name="sum")
    name, value = fut.result(timeout=10)
    assert value == 5 and name.startswith("sum") and name != threading.current_thread().name
    with pytest.raises(ZeroDivisionError):
        background(lambda: 1 / 0).result(timeout=10)


def test_read_ahead_reads_the_next_item_while_this_one_is_used():
    """In order; item k + 1 is being read (in another thread) while the caller holds item k; an
    error is raised at its own item, after the items before it; closed early, the read in
    flight is done before the generator returns."""
    import threading
    import time

    from aveas_format.parallel import read_ahead

    started: list[tuple[int, str]] = []
    done: list[int] = []
    running, most = [0], [0]
    lock = threading.Lock()

    def read(k):
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        started.append((k, threading.current_thread().name))
        try:
            if k == 4:
                raise ValueError("item 4 is broken")
            time.sleep(0.01)
            done.append(k)
            return k * 10
        finally:
            with lock:
                running[0] -= 1

    got = []
    with pytest.raises(ValueError, match="item 4"):
        for v in read_ahead(read, range(6)):
            got.append(v)
            if v == 0:  # (item 1 being read while the caller holds item 0)
                deadline = time.monotonic() + 10
                while len(started) < 2 and time.monotonic() < deadline:
                    time.sleep(0.001)
                assert [k for k, _ in started] == [0, 1]
    assert got == [0, 10, 20, 30] and most[0] == 1  # (one read at a time)
    assert [k for k, _ in started] == [0, 1, 2, 3, 4]  # (none after the failing one)
    assert all(name != threading.current_thread().name for _, name in started)
    started.clear()
    done.clear()
    it = read_ahead(read, range(3))
    assert next(it) == 0
    it.close()  # (item 1 in flight: waited for)
    assert done == [0, 1]
    assert list(read_ahead(read, [])) == []
