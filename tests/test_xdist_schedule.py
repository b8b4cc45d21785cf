"""The xdist units of work (tests/xdist_schedule.py) name modules that exist and group what shares a fixture."""

from __future__ import annotations

from pathlib import Path

from tests.xdist_schedule import GROUPS, HEAVY_FIRST, scope_of

ROOT = Path(__file__).resolve().parent.parent


def test_every_heavy_unit_is_a_module_or_a_group():
    for unit in HEAVY_FIRST:
        assert unit in GROUPS.values() or (ROOT / unit).is_file(), f"{unit}: renamed or gone? (tests/xdist_schedule.py)"
    assert len(set(HEAVY_FIRST)) == len(HEAVY_FIRST)


def test_the_dashboard_modules_are_one_unit_but_the_condition_page_its_own():
    assert scope_of("tests/dashboard/test_pages.py::test_page_loads_clean_with_data[runs]") == "dashboard"
    assert scope_of("tests/dashboard/test_walk.py::test_walk_every_page[1280]") == "dashboard"
    page = "tests/dashboard/test_condition_page.py"
    assert scope_of(f"{page}::test_a_viewer_reads_the_status_but_cannot_change_it") == page
    assert scope_of("tests/db/test_queue.py::TestClaim::test_one") == "tests/db/test_queue.py::TestClaim"
    assert scope_of("tests/e2e/test_readme.py::test_readme_commands_run_verbatim") == "tests/e2e/test_readme.py"


def test_heavy_units_are_handed_out_first_then_loadscope_order():
    from xdist.scheduler.loadscope import LoadScopeScheduling  # noqa: F401  (the scheduler needs xdist)

    from tests.xdist_schedule import cost_ordered_scopes

    cls = cost_ordered_scopes()

    class Node:
        def __init__(self):
            self.sent = []

        def send_runtest_some(self, idx):
            self.sent.append(idx)

    sched = cls.__new__(cls)  # only the queue and the bookkeeping of _assign_work_unit
    from collections import OrderedDict

    ids = ["tests/core/test_a.py::t1", "tests/core/test_a.py::t2", "tests/e2e/test_readme.py::t",
           "tests/dashboard/test_pages.py::t", "tests/condition/test_places_pipeline.py::t"]
    sched.workqueue = OrderedDict()
    for nodeid in ids:
        sched.workqueue.setdefault(sched._split_scope(nodeid), {})[nodeid] = False
    node = Node()
    sched.assigned_work, sched.registered_collections = {}, {node: ids}
    order = []
    while sched.workqueue:
        sched._assign_work_unit(node)
        order.append(list(sched.assigned_work[node])[-1])
    assert order == ["dashboard", "tests/condition/test_places_pipeline.py", "tests/e2e/test_readme.py",
                     "tests/core/test_a.py"]


def test_the_modules_of_a_group_exist():
    for prefix in GROUPS:
        assert (ROOT / prefix).exists(), f"{prefix}: renamed or gone? (tests/xdist_schedule.py)"
    assert scope_of("tests/analytics/test_analytics_api.py::test_x") == "analytics-sim-set"
    assert scope_of("tests/analytics/test_stiffness_index_api.py::test_y") == "analytics-sim-set"
