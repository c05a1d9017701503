"""``import ivobs`` stays light (issue 17): solvers, plotting and the estimator modules are
imported where they are used. And the static method table the lazy registry reads
(``ivobs.estimators.METHODS``) says what the classes say, so it cannot drift from them.

Speed is measured in benchmarks/bench_import.py; these tests check *what* is imported."""

from __future__ import annotations

import importlib
import json
import pkgutil
import subprocess
import sys

import ivobs
import ivobs.estimators as estimators

HEAVY = ("scipy.optimize", "scipy.sparse", "highspy", "cvxpy", "clarabel", "matplotlib", "sympy")


def _modules_after(code: str) -> set[str]:
    """The modules loaded by ``code`` in a fresh interpreter."""
    script = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=120
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def _loaded(mods: set[str], root: str) -> list[str]:
    return sorted(m for m in mods if m == root or m.startswith(root + "."))


def test_import_ivobs_loads_no_solver_plotting_or_method_module() -> None:
    mods = _modules_after("import ivobs")
    assert {root: _loaded(mods, root) for root in HEAVY} == {root: [] for root in HEAVY}
    method_modules = {f"ivobs.estimators.{e.module}" for e in estimators.METHODS.values()}
    assert sorted(method_modules & mods) == []


def test_listing_the_methods_imports_none_of_them() -> None:
    mods = _modules_after("import ivobs; assert len(ivobs.methods()) >= 11")
    assert _loaded(mods, "scipy.optimize") == [] and _loaded(mods, "highspy") == []


def test_asking_for_a_method_imports_its_module_only() -> None:
    mods = _modules_after("import ivobs; ivobs.estimators.get('reachability')")
    assert "ivobs.estimators.reachability" in mods
    assert "ivobs.estimators.exact.estimator" not in mods
    assert _loaded(mods, "highspy") == []


def _all_registered() -> dict[str, type]:
    """Import every module of the estimators package: the classes that register themselves."""
    for mod in pkgutil.walk_packages(estimators.__path__, estimators.__name__ + "."):
        importlib.import_module(mod.name)
    return dict(estimators._REGISTRY)


def test_the_method_table_matches_the_classes() -> None:
    registered = _all_registered()
    table = {
        name: (f"ivobs.estimators.{e.module}", e.cls, e.order)
        for name, e in estimators.METHODS.items()
    }
    found = {
        name: (cls.__module__, cls.__name__, cls.order)
        for name, cls in registered.items()
        if cls.__module__.startswith("ivobs.estimators.")
    }
    assert table == found


def test_methods_order_and_get_agree_with_the_classes() -> None:
    names = ivobs.methods()
    assert names == sorted(names, key=lambda n: (estimators.get(n).order, n))
    assert len(names) == len(set(names)) >= 11
    for name in names:
        assert estimators.get(name).name == name
