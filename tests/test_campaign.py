"""Campaigns: spec validation, job ids, incremental results and resume, failures as rows, local
processes and a Dask LocalCluster (same numbers on every engine, and as ``ivobs compare``)."""

from __future__ import annotations

import hashlib
import json
import os
import sys
import textwrap

import numpy as np
import pytest

from ivobs import IvobsError, campaign, scenarios
from ivobs.cli import main
from ivobs.report import compare

SPEC = """
name = "small"
scenarios = ["servo-motor", "efimov-planar"]
methods = ["interval-split", { name = "zonotope", options = { order = [5, 8] } }]
seeds = [0, 1]
horizon = 40
burn_in = 5
"""  # 2 scenarios x 3 method settings x 2 seeds = 12 jobs


def write(tmp_path, text: str, name: str = "spec.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small grid run in this process: ``{job_id: row}``."""
    path = write(tmp_path_factory.mktemp("ref"), SPEC)
    res = campaign.run_campaign(path, workers=0)
    assert (res.total, res.ran, res.skipped) == (12, 12, 0)
    return {r["job_id"]: r for r in res.rows}


# ------------------------------------------------------------------------------------------
# spec and jobs
# ------------------------------------------------------------------------------------------
def test_grid_expansion_and_stable_ids(tmp_path):
    text = SPEC + 'disturbance = ["vertex", "uniform"]\n'
    spec = campaign.loads_spec(text, base_dir=tmp_path, stem="g")
    jobs = spec.jobs()
    assert len(jobs) == 2 * 2 * 3 * 2
    assert len({j.id for j in jobs}) == len(jobs)
    assert all(len(j.id) == 16 and int(j.id, 16) >= 0 for j in jobs)
    assert [j.id for j in campaign.loads_spec(text).jobs()] == [j.id for j in jobs]
    assert spec.output == tmp_path / "g.csv"
    assert {j.scenario_options["horizon"] for j in jobs} == {40}
    assert sorted({tuple(j.options.items()) for j in jobs}) == [(), (("order", 5),),
                                                                (("order", 8),)]  # fmt: skip
    # the id is a hash of the parameters only: key order does not matter, every value does
    a = campaign.Job("servo-motor", "zonotope", 3, options={"order": 4, "weight": "trace"})
    b = campaign.Job("servo-motor", "zonotope", 3, options={"weight": "trace", "order": 4})
    assert a.id == b.id != campaign.Job("servo-motor", "zonotope", 4, options=a.options).id
    # pinned: changing the hash would make every existing results table unresumable
    assert campaign.Job("servo-motor", "interval-split", 0).id == "e155f4a5d4c13cf0"


def test_job_id_is_the_hash_of_canonical_json():
    params = {"scenario": "servo-motor", "scenario_options": {}, "disturbance": "vertex",
              "method": "interval-split", "options": {}, "seed": 0, "burn_in": None}  # fmt: skip
    text = json.dumps(params, sort_keys=True, separators=(",", ":"))
    assert text == (
        '{"burn_in":null,"disturbance":"vertex","method":"interval-split",'
        '"options":{},"scenario":"servo-motor","scenario_options":{},"seed":0}'
    )
    assert (
        campaign.Job("servo-motor", "interval-split", 0).id
        == (hashlib.sha256(text.encode()).hexdigest()[:16])
    )


GOOD = 'scenarios = ["servo-motor"]\nmethods = ["zonotope"]\n'


@pytest.mark.parametrize(
    "text, expected",
    [
        ('scenarios = ["servo-motor"]\nmethods = [zonotope]\n', ["not valid TOML", "line 2"]),
        ('scenarios = ["servo-motor"]\n', ["missing key 'methods'"]),
        (GOOD + "sedes = [1]\n", ["line 3", "sedes", "unknown key"]),
        ('scenarios = ["servo"]\nmethods = ["zonotope"]\n', ["line 1", "unknown scenario"]),
        ('scenarios = ["servo-motor"]\nmethods = ["kalman"]\n', ["line 2", "unknown method"]),
        (
            GOOD + "[options.zonotope]\nordr = [4]\n",
            ["line 4", "options.zonotope.ordr", "accepted: L, order"],
        ),
        (GOOD + "[options.zonotope]\norder = []\n", ["line 4", "empty list"]),
        (GOOD + "[options.kkl]\ntune = [true]\n", ["line 3", "not in methods"]),
        (GOOD + "seeds = [1, 1]\n", ["line 3", "seeds", "listed twice"]),
        (GOOD + "seeds = [-1]\n", ["seeds", "integer >= 0"]),
        (GOOD + "seeds = { start = 2 }\n", ["seeds", "either stop"]),
        (GOOD + 'disturbance = "gaussian"\n', ["line 3", "unknown disturbance 'gaussian'"]),
        (
            'scenarios = ["cora-2dim"]\nmethods = ["zonotope"]\nhorizon = 10\n',
            ["line 3", "horizon", "none of the scenarios"],
        ),
        (GOOD + "horizon = 0\n", ["horizon", "integer >= 1"]),
        (GOOD + "horizon = 20\nburn_in = 20\n", ["line 4", "burn_in", "leaves no step"]),
        (GOOD + "[scenario_options.servo-motor]\nlength = 3\n", ["line 4", "no option 'length'"]),
        (
            'scenarios = ["servo-motor"]\nmethods = ["zonotope", { name = "zonotope" }]\n',
            ["line 2", "same jobs"],
        ),
        (
            GOOD + 'imports = ["no_such_module_xyz"]\n',
            ["line 3", "imports Python module 'no_such_module_xyz'", "allow_code=True"],
        ),
    ],
)
def test_malformed_specs_name_key_and_line(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(IvobsError) as err:
        campaign.load_spec(path)
    msg = str(err.value)
    assert msg.startswith(str(path))
    for frag in expected:
        assert frag in msg, msg


def test_cli_bad_spec_is_a_clean_error(tmp_path, capsys):
    path = write(tmp_path, GOOD + "[options.zonotope]\nordr = [4]\n")
    assert main(["campaign", str(path)]) == 2
    assert "line 4: options.zonotope.ordr" in capsys.readouterr().err


def test_output_that_is_not_a_results_table(tmp_path):
    path = write(tmp_path, GOOD + 'output = "other.csv"\nhorizon = 20\n')
    (tmp_path / "other.csv").write_text("a,b\n1,2\n")
    with pytest.raises(IvobsError, match="not a results table"):
        campaign.run_campaign(path, workers=0)
    assert (tmp_path / "other.csv").read_text() == "a,b\n1,2\n"  # untouched


# ------------------------------------------------------------------------------------------
# numbers, resume, failures (in this process: fast)
# ------------------------------------------------------------------------------------------
def test_rows_hold_the_numbers_of_ivobs_compare(reference, tmp_path):
    rows = list(reference.values())
    assert all(r["status"] == "ok" and r["contains"] is True for r in rows)
    for r in rows:
        assert r["horizon"] == 40 and r["burn_in"] == 5 and r["error"] is None
        assert len(r["widths"]) == scenarios.get(r["scenario"]).system.nx
        assert r["mean_width"] == pytest.approx(np.mean(r["widths"]), rel=1e-15)
        assert r["design_time"] > 0 and r["run_time"] > 0 and r["valid_from"] >= 0
    # the same numbers as `ivobs compare` on the same record
    for r in rows[:6]:
        sc = scenarios.get(r["scenario"], horizon=40)
        _, (res,) = compare(sc, [r["method"]], disturbance="vertex", seed=r["seed"],
                            burn_in=5, options={r["method"]: r["options"]})  # fmt: skip
        np.testing.assert_allclose(r["widths"], res.mean_width, rtol=1e-12)
    # a real ordering: the zonotope with 8 generators is tighter than with 5
    by = {(r["scenario"], r["method"], r["options"].get("order"), r["seed"]): r for r in rows}
    for sc in ("servo-motor", "efimov-planar"):
        assert by[sc, "zonotope", 8, 0]["mean_width"] < by[sc, "zonotope", 5, 0]["mean_width"]
    # seeds share a design: the second seed reuses it
    reused = [r["design_reused"] for r in rows if r["method"] == "interval-split"]
    assert sorted(reused) == [False, False, True, True]


def test_resume_after_limit_interrupt_and_cut_off_line(tmp_path, reference):
    path = write(tmp_path, SPEC)
    out = tmp_path / "spec.csv"
    first = campaign.run_campaign(path, workers=0, limit=3)
    assert (first.ran, first.skipped, len(first.rows), first.complete) == (3, 0, 3, False)

    class Stop(Exception):
        pass

    seen = []

    def interrupt(row):  # the campaign is killed after two more jobs
        seen.append(row["job_id"])
        if len(seen) == 2:
            raise Stop

    with pytest.raises(Stop):
        campaign.run_campaign(path, workers=0, on_row=interrupt)
    assert len(campaign.read_results(out)) == 5  # both were written before the interrupt

    # a crash in the middle of a line: the cut-off line is dropped and its job rerun
    lines = out.read_text().splitlines(keepends=True)
    out.write_text("".join(lines[:-1]) + lines[-1][:25])
    assert len(campaign.read_results(out)) == 4
    rest = campaign.run_campaign(path, workers=0)
    assert (rest.ran, rest.skipped, rest.complete) == (8, 4, True)
    again = campaign.run_campaign(path, workers=0)
    assert (again.ran, again.skipped) == (0, 12)

    text = out.read_text()
    assert text.endswith("\n") and len(text.splitlines()) == 1 + 12
    rows = {r["job_id"]: r for r in campaign.read_results(out)}
    assert rows.keys() == reference.keys()
    for k, r in rows.items():
        assert r["widths"] == reference[k]["widths"]  # bit for bit, the CSV keeps repr()


PLUGIN = '''
"""Test plugin: a scenario whose simulation fails for seed 1 (an unexpected exception)."""
from ivobs import scenarios


@scenarios.register_scenario("test-flaky", "servo motor; seed 1 raises RuntimeError")
def flaky(horizon: int = 30):
    sc = scenarios.get("servo-motor", horizon=horizon)

    def dist(kind, seed, T):
        if seed == 1:
            raise RuntimeError("boom")
        return None

    sc._disturbance = dist
    return sc
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    (tmp_path / "ivobs_campaign_test_plugin.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "ivobs_campaign_test_plugin"
    scenarios._BUILDERS.pop("test-flaky", None)
    sys.modules.pop("ivobs_campaign_test_plugin", None)


def test_failures_are_rows_and_errors_can_be_retried(tmp_path, plugin, capsys):
    path = write(
        tmp_path,
        f"""
        scenarios = ["tang-example2", "test-flaky"]
        methods = ["interval", "fixed-time"]
        seeds = [0, 1]
        imports = ["{plugin}"]
        summary = "summary.md"
        """,
    )
    # the spec imports a module: refused (nothing run, nothing written) until trusted
    assert main(["campaign", str(path), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert "line 5: imports: imports Python module 'ivobs_campaign_test_plugin'" in err
    assert "--allow-code" in err and not (tmp_path / "spec.csv").exists()
    assert plugin not in sys.modules
    trusted = ["--allow-code"]
    assert main(["campaign", str(path), "--workers", "0", *trusted]) == 1  # an unexpected error
    out = capsys.readouterr().out
    rows = campaign.read_results(tmp_path / "spec.csv")
    assert len(rows) == 8
    status = {(r["scenario"], r["method"], r["seed"]): r for r in rows}
    for seed in (0, 1):  # the design is infeasible: a recorded failure, not a crash
        r = status["tang-example2", "interval", seed]
        assert r["status"] == "failed" and r["error"].startswith("DesignError: interval")
        assert r["mean_width"] is None and r["contains"] is None
        assert status["tang-example2", "fixed-time", seed]["status"] == "ok"
        assert status["test-flaky", "fixed-time", 0]["status"] == "ok"
    for method in ("interval", "fixed-time"):
        r = status["test-flaky", method, 1]
        assert r["status"] == "error"
        assert r["error"].startswith("RuntimeError: boom (at ivobs_campaign_test_plugin.py:")
    assert "0/2" in out and "DesignError" in out and "2 failed, 2 errors" in out
    assert "| tang-example2 | interval | 0/2 |" in (tmp_path / "summary.md").read_text()

    assert main(["campaign", str(path), "--dry-run", *trusted]) == 0
    assert "8 jobs = 2 scenarios x 1 disturbances x 2 method settings x 2 seeds; 8 already" in (
        capsys.readouterr().out
    )
    # --retry-errors reruns the 2 error rows only (failed designs would fail again)
    assert main(["campaign", str(path), "--workers", "0", "--retry-errors", "-q", *trusted]) == 1
    assert "6 already done, 2 run now" in capsys.readouterr().out
    assert len((tmp_path / "spec.csv").read_text().splitlines()) == 1 + 8 + 2
    assert len(campaign.read_results(tmp_path / "spec.csv")) == 8


def test_one_writer_at_a_time(tmp_path):
    out = tmp_path / "r.csv"
    with campaign.ResultsFile(out), pytest.raises(IvobsError, match="another campaign"):
        campaign.ResultsFile(out).__enter__()


# ------------------------------------------------------------------------------------------
# engines: local processes and a Dask cluster give the same rows
# ------------------------------------------------------------------------------------------
def test_local_processes(tmp_path, reference, capsys):
    path = write(tmp_path, SPEC)
    assert main(["campaign", str(path), "--workers", "2"]) == 0
    out = capsys.readouterr().out
    assert "12 run now on 2 local processes" in out and "| servo-motor | zonotope |" in out
    rows = {r["job_id"]: r for r in campaign.read_results(tmp_path / "spec.csv")}
    assert rows.keys() == reference.keys()
    for k, r in rows.items():
        assert r["widths"] == reference[k]["widths"]
    workers = {r["worker"] for r in rows.values()}
    assert f"pid {os.getpid()}" not in workers and len(workers) <= 2


def test_dask_cluster(tmp_path, reference, capsys):
    distributed = pytest.importorskip("distributed")
    path = write(tmp_path, SPEC)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        assert main(["campaign", str(path), "--scheduler", address, "--limit", "7"]) == 0
        assert "7 run now on Dask cluster" in capsys.readouterr().out
        assert main(["campaign", str(path), "--scheduler", address]) == 0  # resume
        assert "7 already done, 5 run now" in capsys.readouterr().out
    rows = {r["job_id"]: r for r in campaign.read_results(tmp_path / "spec.csv")}
    assert rows.keys() == reference.keys()
    for k, r in rows.items():
        assert r["widths"] == reference[k]["widths"]
    assert all(r["worker"].startswith("tcp://") for r in rows.values())


def test_scheduler_errors(tmp_path, monkeypatch):
    path = write(tmp_path, SPEC)
    with pytest.raises(IvobsError, match="cannot connect to the Dask scheduler"):
        campaign.run_campaign(path, scheduler="tcp://127.0.0.1:9", connect_timeout=0.5)
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(IvobsError, match=r"ivobs\[cluster\]"):
        campaign.run_campaign(path, scheduler="tcp://127.0.0.1:9")
    assert not (tmp_path / "spec.csv").exists()  # nothing written before connecting


def test_a_system_file_as_a_campaign_scenario(tmp_path):
    import ivobs

    sc = scenarios.get("servo-motor")
    ivobs.save_system(tmp_path / "plant.toml", sc)
    spec = write(
        tmp_path,
        'scenarios = ["plant.toml", "servo-motor"]\nmethods = ["interval-split"]\n'
        "seeds = [0, 1]\nhorizon = 40\n",
    )
    res = campaign.run_campaign(spec, workers=0)
    rows = [r for r in res.rows if r["scenario"].endswith("plant.toml")]
    assert len(rows) == 2 and all(r["status"] == "ok" for r in rows)
    assert all(r["contains"] for r in rows)
    # the same plant simulated from the file's prior box: the same numbers as the Python API
    plant = ivobs.io.plant.file_scenario(tmp_path / "plant.toml", horizon=40)
    tr = plant.simulate("vertex", 1)
    # (with the comparisons' default: the measurement strips)
    est = ivobs.make_estimator("interval-split", plant.system, x0=plant.x0, strips=True)
    est = est.run(tr.u, tr.y)
    one = next(r for r in rows if r["seed"] == 1)
    assert one["mean_width"] == pytest.approx(float(est.mean_width(4).mean()))
    bad = write(tmp_path, 'scenarios = ["nope.toml"]\nmethods = ["interval-split"]\n', "b.toml")
    with pytest.raises(IvobsError, match="system file 'nope.toml' not found"):
        campaign.load_spec(bad)
