"""Property-based fuzzing (Hypothesis) of what ivobs reads: system files, expressions, logs,
monitor state files and method options. For every input: a result or a clear ``IvobsError``,
never another exception, never more than 10 s; and the families that used to be taken silently
(a log with gaps or an offset start, a decimal exponent or a folded power beyond the limits,
a 64-bit overflow, a state file edited by hand) are refused or read right, checked against an
oracle written here. About a minute in all (``slow``)."""

import contextlib
import json
import math
import signal

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ivobs
from ivobs import IvobsError, scenarios
from ivobs.cli import main
from ivobs.estimators import get
from ivobs.io import loads_system, read_log, save_system, write_log
from ivobs.model.nonlinear import parse

pytestmark = pytest.mark.slow

FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@contextlib.contextmanager
def within(seconds=10.0):
    """Fail (TimeoutError) when the block takes more than ``seconds`` of CPU time: no input may
    hang (CPU time, not wall time: a loaded machine does not make an input hang)."""

    def alarm(*_):
        raise TimeoutError(f"more than {seconds} s of CPU time")

    old = signal.signal(signal.SIGPROF, alarm)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, old)


def clear(fn, *args, **kwargs):
    """``fn(...)``'s result, or None when it raised ``IvobsError``; any other exception (a
    traceback) or a hang fails the test."""
    with within():
        try:
            return fn(*args, **kwargs)
        except IvobsError as exc:
            assert str(exc), "an error must say what is wrong"
            return None


# -- system files ---------------------------------------------------------------------------
SERVO = scenarios.get("servo-motor")
VALUES = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(lambda v: repr(v).replace("inf", "inf")),
    st.sampled_from(["true", '"x"', "[]", "[[]]", "{}", "nan", "-inf", "1e999", "1_000",
                     "'\uff11'", '"\u0661"', "[1, [2]]", "{ lower = [1], upper = [0] }"]),
    st.integers(1, 40).map(lambda n: "[" * n + "1" + "]" * n),
)  # fmt: skip


@pytest.fixture(scope="module")
def servo_text(tmp_path_factory):
    path = tmp_path_factory.mktemp("fuzz") / "s.toml"
    save_system(path, SERVO, method="interval-split")
    return path.read_text()


@FUZZ
@given(data=st.data())
def test_system_files_with_any_value_anywhere(servo_text, data):
    lines = servo_text.splitlines()
    keyed = [i for i, line in enumerate(lines) if " = " in line and not line.startswith("#")]
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.sampled_from(keyed))
        key = lines[i].split(" = ", 1)[0]
        value = data.draw(VALUES)
        lines[i] = f"{key} = {value}"
    text = "\n".join(lines) + "\n"
    spec = clear(loads_system, text)
    if spec is not None:
        big = [int(t) for t in text.replace("[", " ").replace("]", " ").replace(",", " ").split()
               if t.lstrip("-").isdigit()]  # fmt: skip
        assert all(-(2**63) <= v < 2**63 for v in big), "a 64-bit overflow was taken"
        clear(spec.make_estimator)


@FUZZ
@given(depth=st.integers(21, 3000), kind=st.sampled_from(["[", "{a="]))
def test_deep_toml_is_refused(servo_text, depth, kind):
    close = "]" if kind == "[" else "}"
    value = kind * depth + "1" + close * depth
    assert clear(loads_system, servo_text + f"\n[method.options]\nL = {value}\n") is None


# -- expressions ----------------------------------------------------------------------------
NAMES = st.sampled_from(["x1", "x2", "a", "\uff58" + "1", "x\u2081", "pi", "e", "\u03b8"])
NUMBERS = st.one_of(
    st.integers(0, 10**30).map(str),
    st.builds(lambda m, e: f"{m}e{e}", st.integers(1, 99), st.integers(-(10**9), 10**9)),
    st.floats(0, 1e6).map(repr),
)
EXPR = st.recursive(
    st.one_of(NAMES, NUMBERS),
    lambda sub: st.one_of(
        st.builds(lambda a, op, b: f"({a}){op}({b})", sub, st.sampled_from("+-*/"), sub),
        st.builds(lambda a, n: f"({a})**{n}", sub, st.integers(-3000, 3000)),
        st.builds(
            lambda f, a: f"{f}({a})",
            st.sampled_from(["exp", "sin", "log", "sqrt", "tanh", "cosh", "abs"]),
            sub,
        ),
    ),
    max_leaves=12,
)


def _folded_power_beyond(text):
    """An oracle: a numeric exponent beyond the limit written in the text."""
    import re

    return any(abs(int(n)) > parse.MAX_POWER for n in re.findall(r"\*\*(-?\d+)", text))


def _decimal_beyond(text):
    import re

    return any(abs(int(e)) > 400 for e in re.findall(r"\de(-?\d+)", text))


@FUZZ
@given(f=EXPR)
def test_expressions_are_read_or_refused_within_the_limits(f):
    sys = clear(ivobs.NonlinearSystem, f=[f], h=["x1"], states=["x1", "x2"],
                params={"a": (0.9, 1.1)})  # fmt: skip
    if sys is None:
        return
    assert not _folded_power_beyond(f) and not _decimal_beyond(f), f"taken: {f!r}"
    assert "\uff58" not in f and "\u2081" not in f, f"an NFKC-folded name taken: {f!r}"
    est = clear(ivobs.make_estimator, "nl-interval", sys, x0=ivobs.Box([-1, -1], [1, 1]))
    if est is not None:
        clear(est.run, None, np.zeros((3, 1)))


# -- logs -----------------------------------------------------------------------------------
P0 = ivobs.LinearSystem(
    np.array([[0.5, 0.1], [0.0, 0.6]]), None, np.array([[1.0, 0.0]]),
    E=np.eye(2, 3), F=np.array([[0.0, 0.0, 1.0]]), d=ivobs.Box(-0.1 * np.ones(3), 0.1 * np.ones(3)),
)  # fmt: skip
CELLS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.sampled_from(["", "nan", "-nan", "NaN", "inf", "-inf", "1e308", "1e309", "1_0",
                     "\u0661", "\uff11", "0x10", " 2 ", '"3"', "x" * 140_000]),
)  # fmt: skip


@FUZZ
@given(
    steps=st.lists(st.integers(0, 50), min_size=1, max_size=20),
    cells=st.lists(CELLS, min_size=20, max_size=20),
    sort=st.booleans(),
)
def test_logs_are_read_on_their_steps_or_refused(tmp_path, steps, cells, sort):
    steps = sorted(set(steps)) if sort else steps
    path = tmp_path / "log.csv"
    path.write_text("k,y1\n" + "".join(f"{k},{c}\n" for k, c in zip(steps, cells)))
    log = clear(read_log, path, P0)
    if log is None:
        return
    assert steps[0] == 0, "a log starting at another step than the prior's was taken"
    assert steps == sorted(set(steps)), "steps out of order or repeated were taken"
    assert log.T == steps[-1] + 1 and list(log.steps) == list(range(log.T))
    for k, c in zip(steps, cells):  # every row on its own step, read as written
        want = float(c) if c.strip() else math.nan
        got = log.y[k, 0]
        assert (math.isnan(want) and math.isnan(got)) or got == want, (k, c, got)
        assert c.strip().isascii() and "_" not in c
    gaps = sorted(set(range(log.T)) - set(steps))
    assert np.isnan(log.y[gaps]).all() and log.filled[gaps].all()


@FUZZ
@given(steps=st.lists(st.integers(0, 10**16), min_size=1, max_size=6), nu=st.booleans())
def test_far_apart_steps_are_bounded(tmp_path, steps, nu):
    system = SERVO.system if nu else P0
    head = "k,u1,y1,y2" if nu else "k,y1"
    row = "2.0,0.1,0.1" if nu else "0.1"
    path = tmp_path / "log.csv"
    path.write_text(head + "\n" + "".join(f"{k},{row}\n" for k in steps))
    log = clear(read_log, path, system)
    if log is not None:
        assert log.T <= len(steps) + 1_000_000 and log.T == steps[-1] + 1
        assert not nu or log.T == len(steps), "a gap was taken for a system with inputs"


# -- monitor state files --------------------------------------------------------------------
@pytest.fixture(scope="module")
def monitored(tmp_path_factory):
    folder = tmp_path_factory.mktemp("state")
    sc = scenarios.get("servo-motor", horizon=30)
    tr = sc.simulate("vertex", seed=2)
    save_system(folder / "s.toml", sc, method="interval-split")
    write_log(folder / "head.csv", tr.u[:15], tr.y[:15])
    lines = write_log(folder / "log.csv", tr.u, tr.y) or (folder / "log.csv").read_text()
    (folder / "more.csv").write_text("".join(lines.splitlines(keepends=True)[:20]))
    argv = ["monitor", "-s", str(folder / "s.toml"), "--state", str(folder / "st.json")]
    assert main([*argv, "-i", str(folder / "head.csv")]) in (0, 1)
    return folder, argv, (folder / "st.json").read_text()


def _paths(value, prefix=()):
    """Every (path, leaf) of a JSON value."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(value, list) and value:
        for i, v in enumerate(value[:3]):
            yield from _paths(v, (*prefix, i))
    else:
        yield prefix, value


def _nested(n):
    value: list = []
    for _ in range(n):
        value = [value]
    return value


LEAVES = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(), st.text(max_size=5),
    st.just([]), st.just({}), st.integers(1, 500).map(_nested),
)  # fmt: skip


@settings(FUZZ, max_examples=25)  # each example a monitor run
@given(data=st.data(), resign=st.booleans())
def test_edited_state_files_are_refused(monitored, capsys, data, resign):
    folder, argv, text = monitored
    state = json.loads(text)
    paths = [p for p, _ in _paths(state) if p and p[0] != "checksum"]
    path = data.draw(st.sampled_from(paths))
    new = data.draw(LEAVES)
    target = state
    for key in path[:-1]:
        target = target[key]
    if target[path[-1]] == new:
        return
    target[path[-1]] = new
    if resign:  # rewritten by a program: the checksum recomputed, every entry still checked
        from ivobs.io import statefile

        body = {k: state.get(k) for k in ("method", "monitor", "stream")}
        if not all(isinstance(body[k], dict) for k in ("monitor", "stream")):
            return
        statefile.write_state_file(folder / "st.json", str(body["method"]), body["monitor"],
                                   body["stream"])  # fmt: skip
    else:
        (folder / "st.json").write_text(json.dumps(state))
    with within():
        code = main([*argv, "-i", str(folder / "more.csv")])
    out, err = capsys.readouterr()
    (folder / "st.json").write_text(text)  # the original, for the next example
    assert code in (0, 1, 2) and "Traceback" not in err
    if not resign:
        assert code == 2 and "--state" in err and out == "", "an edited state file was taken"


# -- options --------------------------------------------------------------------------------
OPTION_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(), st.text(max_size=8),
    st.lists(st.floats(-10, 10), max_size=4),
    st.builds(lambda s, d: np.zeros(s, dtype=d), st.lists(st.integers(0, 3), max_size=3),
              st.sampled_from([float, int, bool, complex, object, "U3"])),
    st.sampled_from([np.float64(2.0), np.int64(3), np.array(3), np.array("x"), np.nan, -np.inf,
                     10**12, ivobs.Box([0.0], [1.0])]),
)  # fmt: skip
METHODS = [m for m in ivobs.methods() if m not in ("exact",)]  # exact: an LP per option set


@FUZZ
@given(method=st.sampled_from(METHODS), data=st.data())
def test_any_option_value_is_taken_or_refused_by_name(method, data):
    option = data.draw(st.sampled_from(get(method).options()))
    value = data.draw(OPTION_VALUES)
    extra = {"methods": ["interval-split", "zonotope"]} if method == "intersect" else {}
    if option == "methods":
        extra = {}
    with within():
        try:
            ivobs.make_estimator(method, SERVO.system, x0=SERVO.x0, **extra, **{option: value})
        except IvobsError as exc:
            assert str(exc)
