"""A log's step column is honoured by every reader: a row's ``k`` is its step, a gap is a run
of missing samples, a log that starts at another step than the prior's is refused unless the
prior is given for that step (``[x0] step``), and ``run``, ``compare``, ``monitor`` and
``Monitor.check`` agree. The boxes are checked against the true state at the log's own steps,
simulated exactly (rational arithmetic) in this file. Also the cells: ``-nan`` is a missing
sample, other scripts' digits are no number, a byte-order mark is skipped in logs and system
files alike, and a bounds file a system file names is never quoted in an error."""

import json

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError
from ivobs.cli import main
from ivobs.io import load_system, read_log, save_system, write_log
from ivobs.monitor import Monitor
from signplant import contains, plant, simulate

T = 60


def _simulate(sys, x_true0, seed):
    return simulate(sys, seed, T, x_true0)


def _bounds(path):
    """The steps and boxes of ``ivobs run --out``."""
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    cols = lines[0].split(",")
    data = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    lo = data[:, [i for i, c in enumerate(cols) if c.startswith("lower_")]]
    hi = data[:, [i for i, c in enumerate(cols) if c.startswith("upper_")]]
    return [int(k) for k in data[:, 0]], lo, hi


def _log(path, y, keep, start=0):
    """A log of the rows ``keep`` (their steps, from ``start``) of ``y``."""
    lines = ["k,y1", *(f"{start + k},{float(y[k, 0])!r}" for k in keep)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def dropped(tmp_path):
    """A plant, its truth, and a log whose rows 20..24 and 41 were dropped by the logger."""
    sys, x0 = plant(1)
    xs, y = _simulate(sys, [3.5, -2.5], 1)
    save_system(tmp_path / "p.toml", sys, x0=x0, method="interval-split")
    keep = [k for k in range(T) if not (20 <= k < 25 or k == 41)]
    return sys, x0, xs, _log(tmp_path / "gap.csv", y, keep), tmp_path


@pytest.mark.parametrize("seed", range(6))
def test_a_gap_is_missing_samples_and_every_box_holds_the_truth(tmp_path, seed):
    sys, x0 = plant(seed)
    xs, y = _simulate(sys, [3.5, -2.5], seed)
    keep = [k for k in range(T) if k != 30 + seed]  # one dropped row
    log = read_log(_log(tmp_path / "l.csv", y, keep), sys)
    assert log.T == T and list(log.steps) == list(range(T)) and log.filled.sum() == 1
    assert np.isnan(log.y[30 + seed]).all() and not np.isnan(np.delete(log.y, 30 + seed)).any()
    for method in ("interval-split", "zonotope", "fixed-time"):
        res = ivobs.make_estimator(method, sys, x0=x0).run(log.u, log.y)
        valid = range(res.valid_from, T)
        assert contains(res.lower[valid.start :], res.upper[valid.start :], xs, valid), method
        record = Monitor(sys, method, x0=x0).check(log.u, log.y, estimate=res)
        assert not record.alarm.any(), method  # no false alarm after the gap
    record = Monitor(sys, "interval-split", x0=x0).check(log)  # the Log itself
    assert record.alarm.shape == (T,) and not record.alarm.any()
    assert contains(record.lower, record.upper, xs, range(T))


def test_run_and_monitor_label_boxes_with_the_log_steps(dropped, capsys):
    _sys, _x0, xs, log, folder = dropped
    out = folder / "bounds.csv"
    assert main(["run", "-s", str(folder / "p.toml"), "-l", str(log), "--out", str(out)]) == 0
    assert "5 skipped by the log" not in capsys.readouterr().out  # 6 were: 20..24 and 41
    steps, lo, hi = _bounds(out)
    assert steps == list(range(T)) and contains(lo, hi, xs, steps)
    assert main(["monitor", "-s", str(folder / "p.toml"), "-i", str(log)]) == 0
    rows = [line.split(",") for line in capsys.readouterr().out.splitlines()[1:]]
    assert [int(r[0]) for r in rows] == list(range(T))  # one line per step, gap included
    lo = np.array([[float(r[1]), float(r[2])] for r in rows])
    hi = np.array([[float(r[3]), float(r[4])] for r in rows])
    assert contains(lo, hi, xs, range(T)) and all(r[5] == "0" for r in rows)


def test_compare_reads_the_same_steps(dropped, capsys):
    *_, log, folder = dropped
    code = main(["compare", "-s", str(folder / "p.toml"), "-l", str(log),
                 "--methods", "interval-split", "--json", "-"])  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0
    assert json.loads(text[text.index("{") :])["horizon"] == T


def test_an_offset_start_needs_the_prior_of_that_step(tmp_path, capsys):
    sys, x0 = plant(2)
    xs, y = _simulate(sys, [3.5, -2.5], 2)
    late = list(range(10, T))  # the logger started at step 10 of the plant (its 1000)
    log = tmp_path / "late.csv"
    log.write_text("k,y1\n" + "".join(f"{1000 + k - 10},{float(y[k, 0])!r}\n" for k in late))
    save_system(tmp_path / "p.toml", sys, x0=x0, method="interval-split")
    with pytest.raises(IvobsError, match=r"starts at step 1000, but the prior box bounds x\[0\]"):
        read_log(log, load_system(tmp_path / "p.toml"))
    for argv in (["run", "-l", str(log)], ["compare", "-l", str(log)],
                 ["monitor", "-i", str(log)]):  # fmt: skip
        assert main([*argv, "-s", str(tmp_path / "p.toml")]) == 2
        assert "[x0] step = 1000" in capsys.readouterr().err
    # the prior of x[1000] (the plant's step 10) given: accepted, labelled from 1000
    box = ivobs.Box([float(v) - 0.01 for v in xs[10]], [float(v) + 0.01 for v in xs[10]])
    save_system(tmp_path / "p.toml", sys, x0=box, method="interval-split")
    text = (tmp_path / "p.toml").read_text().replace("[x0]\n", "[x0]\nstep = 1000\n")
    (tmp_path / "p.toml").write_text(text)
    spec = load_system(tmp_path / "p.toml")
    assert spec.x0_step == 1000 and read_log(log, spec).start == 1000
    out = tmp_path / "b.csv"
    assert main(["run", "-s", str(tmp_path / "p.toml"), "-l", str(log), "-o", str(out)]) == 0
    steps, lo, hi = _bounds(out)
    assert steps == list(range(1000, 1000 + T - 10)) and contains(lo, hi, xs, late)
    capsys.readouterr()
    assert main(["monitor", "-s", str(tmp_path / "p.toml"), "-i", str(log)]) == 0
    assert capsys.readouterr().out.splitlines()[1].startswith("1000,")


def test_duplicates_huge_jumps_and_gaps_without_inputs_are_refused(dropped, tmp_path):
    sys, _x0, _xs, log, _folder = dropped
    text = log.read_text().splitlines()
    bad = {
        "dup.csv": ([*text[:5], text[4], *text[5:]], "step 3 does not increase"),
        "jump.csv": ([*text[:5], "1000000000000,0.1"], "more than 1000000 missing steps"),
        "neg.csv": (["k,y1", "-1,0.1", "0,0.2"], r"expected a step in 0..2\*\*53"),
    }
    for name, (lines, msg) in bad.items():
        (tmp_path / name).write_text("\n".join(lines) + "\n")
        with pytest.raises(IvobsError, match=msg):
            read_log(tmp_path / name, sys)
    sc = ivobs.scenarios.get("servo-motor", horizon=30)  # a plant with an input
    tr = sc.simulate("vertex", seed=1)
    write_log(tmp_path / "servo.csv", tr.u, tr.y)
    lines = (tmp_path / "servo.csv").read_text().splitlines()
    (tmp_path / "servo.csv").write_text("\n".join(lines[:11] + lines[14:]) + "\n")
    with pytest.raises(IvobsError, match=r"steps 10..12 missing .* inputs"):
        read_log(tmp_path / "servo.csv", sc.system)


def test_minus_nan_is_missing_and_other_digits_are_no_numbers(dropped, tmp_path):
    sys, *_ = dropped
    (tmp_path / "n.csv").write_text("k,y1\n0,-nan\n1,+NaN\n2,0.5\n")
    assert np.isnan(read_log(tmp_path / "n.csv", sys).y[:2]).all()
    for cell in ("\u0661\u0662", "\uff11", "1\u0663"):  # Arabic-Indic, full-width digits
        (tmp_path / "d.csv").write_text(f"k,y1\n0,{cell}\n")
        with pytest.raises(IvobsError, match="digits 0-9"):
            read_log(tmp_path / "d.csv", sys)
    (tmp_path / "d.csv").write_text("k,y\u0661\n0,1.0\n")  # not column y1
    with pytest.raises(IvobsError, match="unexpected column"):
        read_log(tmp_path / "d.csv", sys)


def test_a_byte_order_mark_is_skipped_in_system_files_as_in_logs(dropped):
    sys, _x0, _xs, log, folder = dropped
    path = folder / "p.toml"
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    log.write_bytes(b"\xef\xbb\xbf" + log.read_bytes())
    spec = load_system(path)
    assert ivobs.io.equal_systems(spec.system, sys) and read_log(log, spec).T == T


def test_errors_never_quote_a_file_the_system_file_names(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("root:$6$SECRETHASH:19000:0:99999:7:::\nuser:$6$OTHERHASH:1\n")
    sc = ivobs.scenarios.get("servo-motor")
    save_system(tmp_path / "s.toml", sc)
    text = (tmp_path / "s.toml").read_text()
    for upper in ('["root:$6$SECRETHASH:19000:0:99999:7:::"]', '["nope"]', "[1.0]"):
        (tmp_path / "s.toml").write_text(
            text.replace("upper = [0.0225", f'csv = "{secret}"\nupper = {upper}  # [0.0225', 1)
        )
        with pytest.raises(IvobsError) as err:
            load_system(tmp_path / "s.toml")
        assert "SECRETHASH" not in str(err.value).replace(upper, "")
        assert "OTHERHASH" not in str(err.value) and str(secret) in str(err.value)
