"""``ivobs.config``: one registry of the methods' option defaults. The defaults are the classes'
signatures; a changed default reaches ``make_estimator``, a class called directly and the jobs
of a campaign; an explicit option wins; ``reset_defaults`` and ``using`` restore; bad names are
refused with the valid ones; and docs/options.md documents every option of every method."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError, campaign, config
from ivobs.cli import main
from ivobs.cli.methods_cmd import options_markdown, show_default
from ivobs.estimators import METHODS, get
from ivobs.estimators.option_notes import COMMON, NOTES

DOCS = Path(__file__).resolve().parents[1] / "docs" / "options.md"


@pytest.fixture(autouse=True)
def _clean_defaults():
    config.reset_defaults()
    yield
    config.reset_defaults()


A = np.array([[0.5, 0.1], [0.0, 0.6]])
GAIN = {"L": 0.9 * A}  # A − LC = 0.1 A: the observers need no gain design here


@pytest.fixture(scope="module")
def linear():
    """A stable 2-state plant, both states measured: designed in milliseconds."""
    sys = ivobs.LinearSystem.from_process_measurement(
        A, np.zeros((2, 0)), np.eye(2), E=np.eye(2), F=np.eye(2), w=[0.01, 0.01], v=[0.02, 0.02]
    )
    return sys, ivobs.Box([-1.0, -1.0], [1.0, 1.0])


@pytest.fixture(scope="module")
def henon():
    sys = ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"], h=["x2 + v1"], states=["x1", "x2"],
        params={"a": (1.39, 1.41), "b": 0.3}, d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )  # fmt: skip
    return sys, ivobs.Box([0.2, 0.0], [0.4, 0.2])


# ------------------------------------------------------------------------------------------
# the defaults are the signatures
# ------------------------------------------------------------------------------------------
def test_defaults_are_read_from_the_signatures():
    cls = get("dual-window")
    sig = inspect.signature(cls.__init__).parameters
    assert config.defaults("dual-window") == {
        **{k: sig[k].default for k in ("window", "cache", "refresh", "refresh_tol")},
        "on_inconsistent": "warn",
        "strips": None,
    }
    every = config.defaults()
    assert every["dual-window.window"] == "auto" and every["nl-interval.lag"] == 1
    assert len(every) == sum(len(get(m).options()) for m in ivobs.methods())
    assert list(config.defaults("zonotope")) == get("zonotope").options()


# ------------------------------------------------------------------------------------------
# set_defaults reaches every construction; explicit options win
# ------------------------------------------------------------------------------------------
def test_set_defaults_changes_make_estimator_and_direct_construction(linear, henon):
    sys, x0 = linear
    config.set_defaults("dual-window", window=25)
    config.set_defaults("zonotope", order=7)
    config.set_defaults("nl-interval", lag=2)
    assert config.defaults("dual-window")["window"] == 25
    assert ivobs.make_estimator("dual-window", sys, x0=x0).design.window == 25
    assert get("dual-window")(sys, x0).design.window == 25
    assert ivobs.make_estimator("zonotope", sys, x0=x0, **GAIN).design.order == 7
    assert get("zonotope")(sys, x0, **GAIN).design.order == 7
    nl, nx0 = henon
    assert ivobs.make_estimator("nl-interval", nl, x0=nx0).design.lag == 2
    assert get("nl-interval")(nl, nx0).design.lag == 2
    assert config.overrides() == {
        "dual-window": {"window": 25}, "zonotope": {"order": 7}, "nl-interval": {"lag": 2},
    }  # fmt: skip


def test_explicit_options_win_over_changed_defaults(linear):
    sys, x0 = linear
    config.set_defaults("dual-window", window=25, cache=4)
    est = ivobs.make_estimator("dual-window", sys, x0=x0, window=30)
    assert (est.design.window, est.design.cache) == (30, 4)
    assert get("dual-window")(sys, x0, window=31).design.window == 31


def test_options_of_the_base_class_are_set_per_method(linear):
    sys, x0 = linear
    config.set_defaults("zonotope", on_inconsistent="raise", strips=True)
    zono = ivobs.make_estimator("zonotope", sys, x0=x0, **GAIN)
    assert (zono.on_inconsistent, zono.strips) == ("raise", True)
    dual = ivobs.make_estimator("dual-window", sys, x0=x0, window=5)
    assert (dual.on_inconsistent, dual.strips) == ("warn", True)  # a filter: strips by default
    assert ivobs.make_estimator("reachability", sys, x0=x0, **GAIN).strips is False


def test_values_are_checked_by_the_method_when_it_is_built(linear):
    sys, x0 = linear
    config.set_defaults("dual-window", cache=0)  # accepted here: the method checks values
    with pytest.raises(IvobsError, match=r"^cache: "):
        ivobs.make_estimator("dual-window", sys, x0=x0, window=5)
    with pytest.raises(IvobsError, match=r"^order: expected an integer or None, got an array"):
        config.set_defaults("zonotope", order=np.array([6, 12]))
    config.set_defaults("zonotope", order=np.int64(9))  # a NumPy scalar is its number
    assert config.overrides("zonotope") == {"order": 9}
    assert type(config.overrides("zonotope")["order"]) is int


# ------------------------------------------------------------------------------------------
# reset and using restore
# ------------------------------------------------------------------------------------------
def test_reset_restores_the_class_defaults(linear):
    sys, x0 = linear
    config.set_defaults("zonotope", order=7, on_inconsistent="ignore")
    config.set_defaults("dual-window", window=25)
    config.reset_defaults("zonotope", "order")
    assert config.overrides() == {"zonotope": {"on_inconsistent": "ignore"},
                                  "dual-window": {"window": 25}}  # fmt: skip
    assert ivobs.make_estimator("zonotope", sys, x0=x0, **GAIN).design.order == 20  # 10 nx
    config.reset_defaults("dual_window")  # spelled as make_estimator accepts it
    assert config.defaults("dual-window")["window"] == "auto"
    config.reset_defaults()
    assert config.overrides() == {}
    assert config.defaults("zonotope") == get("zonotope").option_defaults()


def test_using_restores_the_previous_defaults_even_on_an_exception(linear):
    sys, x0 = linear
    config.set_defaults("zonotope", order=7)
    with config.using("zonotope", order=9, weight=np.eye(2)) as effective:
        assert effective["order"] == 9
        assert ivobs.make_estimator("zonotope", sys, x0=x0, **GAIN).design.order == 9
        with config.using("zonotope", order=11):
            assert config.defaults("zonotope")["order"] == 11
        assert config.defaults("zonotope")["order"] == 9
    assert config.overrides() == {"zonotope": {"order": 7}}
    with pytest.raises(RuntimeError, match="boom"), config.using("dual-window", window=25):
        assert config.overrides("dual-window") == {"window": 25}
        raise RuntimeError("boom")
    assert config.overrides() == {"zonotope": {"order": 7}}
    with pytest.raises(IvobsError), config.using("zonotope", ordr=3):
        pass  # pragma: no cover - refused before the block
    assert config.overrides() == {"zonotope": {"order": 7}}


# ------------------------------------------------------------------------------------------
# names are checked
# ------------------------------------------------------------------------------------------
def test_unknown_methods_and_options_are_refused_with_the_valid_names():
    with pytest.raises(IvobsError, match=r"^method: unknown method 'nope'; known methods: "
                                         r"fixed-time, reachability, .*dual-window"):  # fmt: skip
        config.set_defaults("nope", window=3)
    accepted = "window, cache, refresh, refresh_tol, on_inconsistent, strips"
    with pytest.raises(IvobsError, match=rf"^options: dual-window does not accept 'windw'; "
                                         rf"accepted options: {accepted}$"):  # fmt: skip
        config.set_defaults("dual-window", windw=3)
    with pytest.raises(IvobsError, match=r"^method: expected a method name \(str\), got 3"):
        config.defaults(3)
    with pytest.raises(IvobsError, match=r"'lag'"):
        config.reset_defaults("zonotope", "lag")
    with pytest.raises(IvobsError, match=r"name the method"):
        config.reset_defaults(None, "order")
    assert config.overrides() == {}


# ------------------------------------------------------------------------------------------
# campaigns: the jobs carry the changed defaults to the workers
# ------------------------------------------------------------------------------------------
SPEC = """
scenarios = ["servo-motor"]
methods = ["dual-window", { name = "zonotope", options = { order = [5, 8] } }]
seeds = [0]
horizon = 40
"""


def test_campaign_jobs_carry_the_changed_defaults():
    plain = campaign.loads_spec(SPEC).jobs()
    with config.using("zonotope", order=12, on_inconsistent="ignore", strips=False):
        with config.using("dual-window", window=np.int64(25)):
            jobs = campaign.loads_spec(SPEC).jobs()
    assert [j.options for j in jobs] == [
        {"window": 25},
        {"order": 5, "on_inconsistent": "ignore"},  # the grid wins; strips stays the command's
        {"order": 8, "on_inconsistent": "ignore"},
    ]
    assert not {j.id for j in jobs} & {j.id for j in plain}
    assert [j.id for j in campaign.loads_spec(SPEC).jobs()] == [j.id for j in plain]
    bad = pytest.raises(IvobsError, match=r"^window: the default of dual-window .* Box")
    with config.using("dual-window", window=ivobs.Box([0.0], [1.0])), bad:
        campaign.loads_spec(SPEC).jobs()


# ------------------------------------------------------------------------------------------
# the documentation: every option, with when to change it; the CLI says the same
# ------------------------------------------------------------------------------------------
def _doc_tables() -> dict[str, dict[str, list[str]]]:
    """docs/options.md: section (method, or "Every method") -> option -> its row's cells."""
    out: dict[str, dict[str, list[str]]] = {}
    section = ""
    for line in DOCS.read_text(encoding="utf-8").splitlines():
        if line.startswith("## "):
            section = line[3:].strip("` ")
            out[section] = {}
        elif line.startswith("| `") and section:
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]
            out[section][cells[0].strip("`")] = cells
    return out


def test_every_option_of_every_method_is_documented_with_when_to_change_it():
    tables = _doc_tables()
    for name in METHODS:
        cls = get(name)
        for option, default in cls.option_defaults().items():
            row = tables[name].get(option) or tables["Every method"].get(option)
            assert row is not None, f"{name}: option {option!r} is not in docs/options.md"
            assert len(row) == 4 and row[2] and row[3], f"{name}.{option}: empty text"
            assert row[1] == f"`{show_default(default)}`", (name, option, row[1])


def test_the_notes_name_only_options_that_exist():
    for name, notes in NOTES.items():
        assert set(notes) <= set(get(name).options()), name
    assert set(COMMON) == set(ivobs.Estimator.options())


def test_the_documented_tables_are_those_the_cli_prints():
    text = DOCS.read_text(encoding="utf-8")
    block = text.split("-->\n\n", 1)[1].split("\n\n<!-- End", 1)[0]
    assert block == options_markdown(), (
        "docs/options.md is stale: paste the output of `ivobs methods --options --markdown`"
    )


def test_methods_options_on_the_command_line(capsys):
    assert main(["methods", "--options", "dual-window"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0] == "dual-window"
    for option in get("dual-window").options():
        assert re.search(rf"^  {option} = ", out, flags=re.M), option
    assert "  window = 'auto'" in out and out.count("When to change it:") == 6
    assert main(["methods", "--options"]) == 0
    listed = [ln for ln in capsys.readouterr().out.splitlines() if ln and not ln[0].isspace()]
    assert listed == ivobs.methods()
    assert main(["methods", "--options", "zonotope", "--markdown"]) == 0
    md = capsys.readouterr().out.splitlines()
    assert md[0] == "| option | default | what it does | when to change it |"
    assert [ln.split(" | ")[0].strip("| `") for ln in md[2:]] == get("zonotope").options()
    assert main(["methods", "--options", "nope"]) == 2
    assert "unknown method 'nope'" in capsys.readouterr().err
