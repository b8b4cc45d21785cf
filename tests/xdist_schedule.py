"""How ``./scripts/test.sh`` shares the tests among its pytest-xdist workers (``-n 4 --dist loadscope``).

pytest-xdist's ``loadscope`` keeps a module's tests in one worker (its module fixtures are made once) and
hands the modules out by their number of tests, largest first. Two things that costs on this suite:

- **Session fixtures made once per worker.** The modules of :data:`GROUPS` share a session fixture that
  is expensive to make and cannot be cached on disk (a running service): they form one unit of work, so
  one worker makes it.
- **The tail.** A module of few tests but a long set-up (a history processed through the real service)
  came last and ran alone while the other worker had finished. The modules of :data:`HEAVY_FIRST` are
  handed out first, longest first (by the suite's ``--durations``), so the
  short modules fill the other worker meanwhile and the two end together.

:func:`cost_ordered_scopes` is installed by ``pytest_xdist_make_scheduler`` in tests/conftest.py; a run
without xdist (``-p no:xdist``, ``TRACKVKF_TEST_WORKERS=0``) does not use it. A module missing from both
lists is scheduled as ``loadscope`` does.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

__all__ = ["GROUPS", "HEAVY_FIRST", "scope_of", "cost_ordered_scopes", "make_scheduler"]

#: module path or directory prefix → the session fixture its modules share (one unit of work); a
#: module of :data:`HEAVY_FIRST` inside a directory that does not use the fixture stays a unit of its own
GROUPS: dict[str, str] = {
    # the `dashboard` service (uvicorn + workers on a copy of the processed demo, a run simulated for
    # the upload test, the engineer's login): ~15 s per worker that makes it
    "tests/dashboard/": "dashboard",
    # the analytics' `sim_set` (three runs through the pipeline, ~90 s): a cached data set, but a second
    # worker asking for it while the first builds it would wait idle for the lock
    "tests/analytics/test_analytics_api.py": "analytics-sim-set",
    "tests/analytics/test_stiffness_index_api.py": "analytics-sim-set",
}

#: units of work handed out first, longest first (rough seconds of set-up + tests on the 2-core CI
#: machine, from the suite's ``--durations`` list; the order matters, not the figures)
HEAVY_FIRST: tuple[str, ...] = (
    "dashboard",                                        # ~390 s: pages, walk, languages, map, wheels, CSP
    "tests/dashboard/test_condition_page.py",           # ~200 s: 10-run history through the service
    "analytics-sim-set",                                # ~130 s: the sim_set build and its two API modules
    "tests/condition/test_places_pipeline.py",          # ~130 s: 10-run planted history
    "tests/e2e/test_worker_faults.py",                  # ~100 s: SIGKILL mid-job per backend
    "tests/e2e/test_backup_restore.py",                 # ~90 s: two backends, three runs each
    "tests/analytics/test_index_across_speed_profiles.py",  # ~90 s: two data sets
    "tests/condition/test_grinding_pipeline.py",        # ~70 s: 10-run rough history
    "tests/condition/test_condition_store.py",          # ~60 s: 12-run store histories, five of them
    "tests/condition/test_real_line_pipeline.py",       # ~45 s: 6 runs of the real line, 1.2 km
    "tests/e2e/test_readme.py",                         # ~55 s: the README's commands verbatim
    "tests/e2e/test_refactor_identity.py",              # ~50 s: the processed demo's fingerprint
    "tests/faults/test_worker_supervision.py",          # ~50 s: supervised worker processes
    "tests/e2e/test_scaleout_faults.py",                # ~50 s: competing workers per backend, three faults on one
    "tests/db/test_display_arrays.py",                  # ~40 s: the SQL path per backend
    "tests/worker/test_tasks.py",                       # ~40 s: fan-out against the local loop
)


def scope_of(nodeid: str) -> str:
    """The unit of work of test ``nodeid``: its group (:data:`GROUPS`), else its module (or class)."""
    module = nodeid.split("::", 1)[0]
    if module not in HEAVY_FIRST:
        for prefix, group in GROUPS.items():
            if module.startswith(prefix):
                return group
    return nodeid.rsplit("::", 1)[0]


def _rank(scope: str) -> int:
    return HEAVY_FIRST.index(scope) if scope in HEAVY_FIRST else len(HEAVY_FIRST)


def make_scheduler(config: Any, log: Any) -> Any:
    """A :func:`cost_ordered_scopes` scheduler for ``--dist loadscope`` runs, else None (xdist's own)."""
    if config.getvalue("dist") != "loadscope":
        return None
    return cost_ordered_scopes()(config, log)


@lru_cache(maxsize=1)
def cost_ordered_scopes() -> type:
    """The scheduler class (made on first use: it needs xdist)."""
    from xdist.scheduler.loadscope import LoadScopeScheduling

    class CostOrderedScopes(LoadScopeScheduling):
        """``loadscope`` with the units of :func:`scope_of`, :data:`HEAVY_FIRST` handed out first."""

        def _split_scope(self, nodeid: str) -> str:
            return scope_of(nodeid)

        def _assign_work_unit(self, node: Any) -> None:
            # the heaviest unit still waiting (min is stable: otherwise loadscope's own order)
            scope = min(self.workqueue, key=_rank)
            self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

    return CostOrderedScopes
