"""Inputs that used to end in a traceback or a silent wrong answer now give a clear
``IvobsError`` naming the argument (or, for ``numpy.ma``, the right answer): TOML integers
beyond 64 bits and deep nesting, deeply nested JSON states, option values given as NumPy
arrays, CSV inputs near the float range and fields over csv's 128 KiB, a restored step count of
``10**30``, and masked samples, which are missing samples."""

import json

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError, scenarios
from ivobs.cli import main
from ivobs.estimators import get
from ivobs.io import loads_system, save_system, write_log
from ivobs.testing import adversarial_run

BIG = "1" + "0" * 400


@pytest.fixture(scope="module")
def servo_text(tmp_path_factory):
    sc = scenarios.get("servo-motor")
    path = tmp_path_factory.mktemp("servo") / "s.toml"
    save_system(path, sc, method="interval-split")
    return path.read_text()


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("[1.0, 0.1, 0.0],", f"[{BIG}, 0.1, 0.0],", "system.A"),
        ("dt = true", f"dt = {BIG}", "system.dt"),
        ("lower = [-0.2, -0.2, -0.2]", f"lower = [-{BIG}, -0.2, -0.2]", "x0.lower"),
        ('name = "interval-split"', f'name = "interval-split"\noptions = {{ L = {BIG} }}',
         "method.options.L"),
        ("dt = true", "dt = 9223372036854775808", "system.dt"),  # 2**63
    ],
)  # fmt: skip
def test_toml_integers_beyond_64_bits_name_their_key(servo_text, old, new, key):
    assert old in servo_text
    with pytest.raises(IvobsError, match=rf"line \d+: {key}: an integer of \d+ bits, beyond"):
        loads_system(servo_text.replace(old, new, 1))


@pytest.mark.parametrize(
    "extra, what",
    [
        ("\n[extra]\nx = " + "[" * 5000 + "]" * 5000, "nested too deeply"),
        ("\n[method.options]\nL = " + "[" * 30 + "1" + "]" * 30, "nested more than 20 levels"),
        ("\n[method.options]\nL = " + "{a=" * 500 + "1" + "}" * 500, "nested"),
        ("\nx = 1" + "0" * 5000, "not valid TOML"),
    ],
)
def test_deep_or_huge_toml_values_are_clear_errors(servo_text, extra, what):
    with pytest.raises(IvobsError, match=what):
        loads_system(servo_text + extra)


def test_deeply_nested_json_states_are_clear_errors(tmp_path, capsys):
    sc = scenarios.get("servo-motor", horizon=20)
    save_system(tmp_path / "s.toml", sc, method="interval-split")
    tr = sc.simulate("vertex", seed=1)
    write_log(tmp_path / "l.csv", tr.u, tr.y)
    (tmp_path / "st.json").write_text("[" * 100_000 + "]" * 100_000)
    argv = ["monitor", "-s", str(tmp_path / "s.toml"), "-i", str(tmp_path / "l.csv")]
    assert main([*argv, "--state", str(tmp_path / "st.json")]) == 2
    assert "nested too deeply" in capsys.readouterr().err
    deep = 1.0
    for _ in range(100_000):
        deep = [deep]
    est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)
    saved = est.state()
    saved["state"]["lo"] = {"array": deep, "shape": [3]}
    with pytest.raises(IvobsError, match="'lo'"):
        est.restore(saved)


def _scalar_options():
    """(method, option) for every option declared a string, a flag or a number."""
    out = []
    for name in ivobs.methods():
        kinds = get(name).__init__.__annotations__
        for opt in get(name).options():
            kind = str(kinds.get(opt, ""))
            if kind and all(p.strip() in ("str", "bool", "int", "float", "None")
                            for p in kind.split("|")):  # fmt: skip
                out.append((name, opt))
    return out


@pytest.mark.parametrize("method, option", _scalar_options())
def test_option_values_given_as_numpy_arrays_are_refused_by_name(method, option):
    sc = scenarios.get("servo-motor")
    extra = {"methods": ["interval-split", "zonotope"]} if method == "intersect" else {}
    for value in (np.array([1.0, 2.0]), np.array(["a", "b"]), np.zeros((2, 2))):
        with pytest.raises(IvobsError, match=rf"^{option}: expected .*, got an array"):
            ivobs.make_estimator(method, sc.system, x0=sc.x0, **extra, **{option: value})


def test_an_array_option_in_a_system_file_names_its_line(servo_text):
    text = servo_text.replace('name = "interval-split"', 'name = "interval-split"\n'
                              "options = { gain = [1.0, 2.0] }")  # fmt: skip
    spec = loads_system(text)
    with pytest.raises(IvobsError, match=r"line \d+: method\.options\.gain: expected a string"):
        spec.make_estimator()


def test_csv_inputs_near_the_float_range_and_long_fields(tmp_path, capsys):
    sc = scenarios.get("servo-motor", horizon=20)
    save_system(tmp_path / "s.toml", sc, method="interval-split")
    tr = sc.simulate("vertex", seed=1)
    u = tr.u.copy()
    u[5] = 1e308
    write_log(tmp_path / "l.csv", u, tr.y)
    for method in ("interval-split", "reachability", "kkl"):
        code = main(["run", "-s", str(tmp_path / "s.toml"), "-l", str(tmp_path / "l.csv"),
                     "-m", method])  # fmt: skip
        out, err = capsys.readouterr()
        assert code in (1, 2) and ("ALARMS" in out or "ivobs: error: " in err), (out, err)
    write_log(tmp_path / "l.csv", tr.u, tr.y)
    text = (tmp_path / "l.csv").read_text().replace("2.0,", "2" + "0" * 140_000 + ",", 1)
    (tmp_path / "long.csv").write_text(text)
    assert main(["run", "-s", str(tmp_path / "s.toml"), "-l", str(tmp_path / "long.csv")]) == 2
    assert "line 2: not a CSV row (field larger than field limit" in capsys.readouterr().err


def test_a_step_count_beyond_2_53_is_refused_on_restore():
    sc = scenarios.get("servo-motor", horizon=4)
    tr = sc.simulate("vertex", seed=1)
    for method in ("interval-split", "dual-window", "zonotope"):
        est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
        est.step(tr.u[0], tr.y[0])
        saved = json.loads(json.dumps(est.state()))
        saved["state"]["k"] = 10**30
        with pytest.raises(IvobsError, match=r"entry 'k': expected the step count"):
            est.restore(saved)


@pytest.mark.parametrize("method", ["fixed-time", "interval-split", "zonotope"])
def test_masked_samples_are_missing_samples(method):
    sc = scenarios.get("servo-motor", horizon=60)
    tr = adversarial_run(sc.system, sc.x0, 60, seed=2)
    y = np.ma.masked_array(tr.y.copy(), mask=np.zeros(tr.y.shape, dtype=bool))
    y[20:26, 1] = tr.y[20:26, 1] + 0.4  # a glitch the logger masked out
    y.mask[20:26, 1] = True
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    res = est.run(tr.u, y)
    assert res.missing[20:26].all() and not res.inconsistent.any()
    assert res.contains(tr.x)[res.valid_from :].all()
    est.reset()
    box = [est.step(tr.u[k], y[k]) for k in range(30)][-1]
    assert np.allclose(box.lo, res.lower[29]) and np.allclose(box.hi, res.upper[29])
    u = np.ma.masked_array(tr.u, mask=np.zeros(tr.u.shape, dtype=bool))
    u.mask[3, 0] = True
    with pytest.raises(IvobsError, match=r"u: NaN at index \(3, 0\); this signal must be known"):
        est.run(u, tr.y)
