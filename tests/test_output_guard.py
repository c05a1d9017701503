"""One output guard (``check_distinct``) for every command that writes: no output is an input
(the system file, the log, a bounds file it names, a campaign's spec or plant files), also
through symbolic or hard links, and no two outputs are one file. A write that fails (a full
disk) is a clear error naming the file, whose previous version is intact."""

import errno
import os

import numpy as np
import pytest

from ivobs import IvobsError, campaign, scenarios
from ivobs.cli import main
from ivobs.io import save_system, write_log

SPEC = 'scenarios = ["servo-motor", "plant.toml"]\nmethods = ["interval-split"]\nhorizon = 30\n'


@pytest.fixture
def plant(tmp_path):
    """A servo system file whose upper bounds come from a CSV file, and a log of 40 steps."""
    sc = scenarios.get("servo-motor", horizon=40)
    tr = sc.simulate("vertex", seed=3)
    save_system(tmp_path / "plant.toml", sc, method="interval-split")
    hi = ", ".join(repr(float(v)) for v in np.atleast_1d(sc.system.d.hi))
    head = ",".join(f"h{i}" for i in range(sc.system.nd))
    (tmp_path / "bounds.csv").write_text(f"{head}\n" + f"{hi}\n" * 40)
    cols = ", ".join(f'"h{i}"' for i in range(sc.system.nd))
    text = (tmp_path / "plant.toml").read_text()
    (tmp_path / "plant.toml").write_text(
        text.replace(f"upper = [{hi}]", f'csv = "bounds.csv"\nupper = [{cols}]')
    )
    write_log(tmp_path / "log.csv", tr.u, tr.y)
    os.symlink(tmp_path / "log.csv", tmp_path / "sym-log.csv")
    os.link(tmp_path / "plant.toml", tmp_path / "hard-plant.toml")
    os.symlink(tmp_path / "bounds.csv", tmp_path / "bounds-link.png")
    return tmp_path


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize(
    "option, target, clash",
    [
        ("--json", "log.csv", "--log"),
        ("--json", "sym-log.csv", "--log"),
        ("--html", "plant.toml", "--system"),
        ("--html", "hard-plant.toml", "--system"),
        ("--plot", "bounds-link.png", "--system's [disturbance] csv"),
    ],
)
def test_compare_never_overwrites_its_inputs(plant, capsys, option, target, clash):
    before = _files(plant)
    argv = ["compare", "-s", str(plant / "plant.toml"), "-l", str(plant / "log.csv")]
    code = main([*argv, "--methods", "interval-split", option, str(plant / target)])
    err = capsys.readouterr().err
    assert code == 2 and f"{option}, {clash}: " in err and "would overwrite it" in err, err
    assert _files(plant) == before


def test_compare_outputs_are_two_files(plant, capsys):
    os.symlink(plant / "r.json", plant / "link.html")
    argv = ["compare", "servo-motor", "--methods", "interval-split"]
    code = main([*argv, "--json", str(plant / "r.json"), "--html", str(plant / "link.html")])
    assert code == 2 and "--json, --html: both write" in capsys.readouterr().err


@pytest.mark.parametrize("key", ["summary", "output"])
@pytest.mark.parametrize("target", ["plant.toml", "hard-plant.toml", "bounds.csv"])
def test_a_campaign_never_writes_over_its_plant_files(plant, capsys, key, target):
    spec = plant / "spec.toml"
    spec.write_text(SPEC + f'{key} = "{target}"\n')
    before = _files(plant)
    assert main(["campaign", str(spec), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert f"{key}, " in err and "plant.toml" in err and "would overwrite it" in err, err
    assert _files(plant) == before
    with pytest.raises(IvobsError, match="would overwrite it"):
        campaign.run_campaign(spec, workers=0)
    campaign.load_spec(spec)  # the spec still loads: nothing was written


def test_figures_go_through_the_guard(tmp_path, capsys):
    out = tmp_path / "figs"
    out.mkdir()
    os.symlink(out / "wang2020_fig1.png", out / "wang2020_fig2.png")  # two figures, one file
    code = main(["figures", "--paper", "Wang2020", "--out", str(out)])
    assert code == 2 and "both write" in capsys.readouterr().err


def _full_disk(monkeypatch):
    """Every atomic write fails as on a full disk (the temporary file cannot be completed)."""

    def replace(src, dst):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("ivobs.io.atomic.os.replace", replace)


def test_a_full_disk_names_the_file_and_keeps_its_previous_version(plant, capsys, monkeypatch):
    out = plant / "bounds-out.csv"
    out.write_text("the previous version\n")
    _full_disk(monkeypatch)
    argv = ["run", "-s", str(plant / "plant.toml"), "-l", str(plant / "log.csv"), "-o", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"cannot write {str(out)!r}: No space left on device" in err
    assert "previous version is intact" in err and out.read_text() == "the previous version\n"
    assert sorted(p.name for p in plant.iterdir() if p.name.startswith(".")) == []  # no temp
    state = plant / "state.json"
    argv = ["monitor", "-s", str(plant / "plant.toml"), "-i", str(plant / "log.csv")]
    assert main([*argv, "--state", str(state)]) == 2
    assert f"cannot write {str(state)!r}: No space left" in capsys.readouterr().err


def test_a_full_disk_stops_a_campaign_with_its_rows_intact(plant, monkeypatch, capsys):
    spec = plant / "spec.toml"
    spec.write_text(SPEC)
    assert main(["campaign", str(spec), "--workers", "0", "--limit", "1", "-q"]) == 0
    table = (plant / "spec.csv").read_text()

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def write(self, text):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name):
            return getattr(self.fh, name)

    enter = campaign.ResultsFile.__enter__

    def full_enter(self):
        enter(self)
        self.fh = Full(self.fh)
        return self

    monkeypatch.setattr(campaign.ResultsFile, "__enter__", full_enter)
    assert main(["campaign", str(spec), "--workers", "0", "-q"]) == 2
    err = capsys.readouterr().err
    assert "cannot append to" in err and "No space left" in err and "rows written" in err
    assert (plant / "spec.csv").read_text() == table
