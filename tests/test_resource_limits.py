"""Bounded work from any file: the limits on expressions (decimal exponents, exact constants,
folded powers, constants beyond the float range) and on campaign sizes (jobs, steps, record
sizes against the stated budget, which ``allow_large`` lifts) are checked before the work, and
a request beyond one is a clear error naming it. Each case runs in a forked process killed
after 10 s: a compute bomb fails the test instead of hanging it."""

import multiprocessing
import sys

import pytest

import ivobs
from ivobs import IvobsError
from ivobs.campaign import loads_spec

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="fork")


def _child(conn, fn, args):
    try:
        fn(*args)
        conn.send(("accepted", ""))
    except IvobsError as exc:
        conn.send(("error", str(exc)))
    except BaseException as exc:  # a traceback: what these tests refuse
        conn.send(("traceback", f"{type(exc).__name__}: {exc}"[:300]))


def _outcome(fn, *args, seconds=10.0):
    """``(kind, message)`` of ``fn(*args)`` in a forked process; ``("hang", "")`` when it does
    not end within ``seconds`` (the process is then killed)."""
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, fn, args))
    proc.start()
    child.close()
    ready = parent.poll(seconds)
    if not ready:
        proc.kill()
        proc.join()
        return "hang", ""
    out = parent.recv()
    proc.join()
    return out


def _nonlinear(f):
    ivobs.NonlinearSystem(f=[f], h=["x1"], states=["x1"])


@pytest.mark.parametrize(
    "expression, message",
    [
        ("1e999999999*x1", "decimal exponent of '1e999999999' beyond the limit of +-400"),
        ("x1 + 1e-999999999", "decimal exponent"),
        ("((x1**1000)**1000)**1000", "exponent 1000000 (powers folded), beyond the limit"),
        ("x1**700*x1**700", "exponent 1400 (powers folded)"),
        ("((9**999)**999)**999", "exact constant of about"),
        ("exp(999**999)", "exact constant of about 9990 bits, beyond the limit of 4096 bits"),
        ("2**(10**6/3)*x1", "exponent 1000000/3 beyond the limit of +-1000"),
        ("exp(exp(exp(100)))*x1", "the constant exp(exp(100)) is beyond the limit of +-1e+300"),
        ("exp(1000)*x1", "the constant exp(1000) is beyond"),
        ("pi**700 + x1", "the constant pi**700 is beyond"),
        ("1" + "0" * 2000 + "*x1", "exact constant of 6644 bits"),
    ],
)
def test_expression_bombs_are_refused_naming_the_limit(expression, message):
    kind, text = _outcome(_nonlinear, expression)
    assert kind == "error", (kind, text)
    assert message in text and f"f[0] = {expression!r}"[:40] in text, text


@pytest.mark.parametrize(
    "expression", ["x1**1000", "1e-300*x1 + 1e300", "(x1 + 1)**999 / 7**999", "exp(690)*x1"]
)
def test_expressions_within_the_limits_are_accepted(expression):
    assert _outcome(_nonlinear, expression) == ("accepted", "")


BOTH = '"servo-motor", "heat-1d"'


def _spec(extra, scenarios='"servo-motor", "heat-1d"'):
    loads_spec(f'scenarios = [{scenarios}]\nmethods = ["interval-split"]\n' + extra)


@pytest.fixture(scope="module", autouse=True)
def _warm():
    """Import and build in this process what every case uses, so that each forked case does
    only its own work."""
    _spec("horizon = 50")
    _nonlinear("x1**2")


@pytest.mark.parametrize(
    "extra, message, scenarios",
    [
        (
            "seeds = { start = 0, stop = 1000000000000 }",
            "seeds.stop: seeds: 1000000000000 jobs",
            BOTH,
        ),
        ("seeds = { count = 1000000000 }", "seeds.count: seeds: 1000000000 jobs", BOTH),
        ("horizon = 1000000000", "horizon: 1000000000 steps, beyond the campaign budget", BOTH),
        ("[scenario_options.heat-1d]\nnx = 100000000", "nx: 100000000 states, beyond", BOTH),
        ("seeds = { count = 2000 }\nhorizon = 1000000", "steps over all jobs", '"servo-motor"'),
        (
            "[options.interval-split]\ngain = ["
            + ", ".join(['"width"'] * 400)
            + "]\nL = ["
            + ", ".join(["1.0"] * 400)
            + "]",
            "the options grid of interval-split: 160000 jobs",
            BOTH,
        ),
    ],
)
def test_campaign_sizes_are_checked_against_the_budget_first(extra, message, scenarios):
    kind, text = _outcome(_spec, extra, scenarios)
    assert kind == "error" and message in text and "--allow-large" in text, (kind, text)


def test_the_budget_is_stated_and_allow_large_lifts_it(monkeypatch, tmp_path, capsys):
    from ivobs.campaign import budget
    from ivobs.cli import main

    assert budget.BUDGET == budget.Budget(100_000, 1_000_000_000, 10_000_000, 100_000)
    monkeypatch.setattr("ivobs.campaign.spec.BUDGET", budget.Budget(jobs=5))
    text = 'scenarios = ["servo-motor"]\nmethods = ["interval-split"]\nhorizon = 20\n'
    text += "seeds = { count = 6 }\n"
    with pytest.raises(IvobsError, match="6 jobs, beyond the campaign budget of 5 jobs"):
        loads_spec(text)
    assert len(loads_spec(text, allow_large=True).jobs()) == 6
    (tmp_path / "s.toml").write_text(text)
    assert main(["campaign", str(tmp_path / "s.toml"), "--dry-run"]) == 2
    assert "--allow-large" in capsys.readouterr().err
    assert main(["campaign", str(tmp_path / "s.toml"), "--dry-run", "--allow-large"]) == 0


def test_a_dual_window_cache_beyond_memory_is_refused():
    sc = ivobs.scenarios.get("servo-motor")
    for options in ({"cache": 10**12}, {"window": 10**9}):
        with pytest.raises(IvobsError, match="multiplier cache holds"):
            ivobs.make_estimator("dual-window", sc.system, x0=sc.x0, **options)
