"""Errors where they arise: only configuration and input errors are "bad input" (exit 2);
an internal failure is a bug (traceback, exit 1), also when it is a ValueError from NumPy;
a figure that cannot be drawn is a note and the run's data still land."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from conftest import base_dict
from pmdsim.cli import app
from pmdsim.config import parse_config

from test_run_signals import _toml


@pytest.fixture
def config_file(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text(_toml(base_dict()))
    return path


@pytest.mark.parametrize("error", [RuntimeError("a bug"),
                                   ValueError("operands could not be broadcast together")])
def test_an_internal_failure_is_a_traceback_not_bad_input(monkeypatch, tmp_path, config_file,
                                                          error):
    import pmdsim.run.simulate as sim_mod

    def broken(*args, **kwargs):
        raise error

    monkeypatch.setattr(sim_mod, "plan_run", broken)
    result = CliRunner().invoke(app, ["simulate", str(config_file), "-o", str(tmp_path / "o")])
    assert result.exit_code == 1
    assert result.exception is error  # propagated as is: Python prints the traceback
    assert "error: " not in result.output


def test_bad_input_is_exit_2_without_traceback(tmp_path, config_file):
    bad = tmp_path / "bad.toml"
    bad.write_text(config_file.read_text().replace("n_rays = 48", "n_rays = nan"))
    result = CliRunner().invoke(app, ["simulate", str(bad), "-o", str(tmp_path / "o")])
    assert result.exit_code == 2 and "sampling.n_rays" in result.output
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)


def test_a_figure_that_cannot_be_drawn_is_a_note_and_the_data_land(monkeypatch, tmp_path):
    import pmdsim.run.figures as figures
    from pmdsim import load_run
    from pmdsim.run import run_simulation

    real = figures.draw_one

    def broken(ds, name, *args, **kwargs):
        if name == "setup":
            raise RuntimeError("matplotlib exploded")
        return real(ds, name, *args, **kwargs)

    monkeypatch.setattr(figures, "draw_one", broken)
    cfg = parse_config(base_dict())
    result = run_simulation(cfg, tmp_path / "out", figures=True)
    assert any("could not be drawn" in n and "matplotlib exploded" in n for n in result.notes)
    assert result.figure_paths  # the other figures were drawn
    ds = load_run(result.outdir)
    assert "fringes" in ds and (result.outdir / "pmdsim-run.json").is_file()
