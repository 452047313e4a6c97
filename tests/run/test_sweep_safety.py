"""Sweeps claimed and written safely (pmdsim.run.sweep): a second sweep on the same folder is
refused at once and leaves nothing behind; temporary stores of dead processes are removed;
a point whose write fails, or that is killed mid-write, is not marked done; a scheduler
address where nothing answers fails fast naming --scheduler."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from pmdsim.config import parse_config
from pmdsim.run.sweep import (STORE_NAME, _open_or_create, claim_sweep, compute_point,
                              done_mask, remove_stale_stores, run_sweep)
from pmdsim.studies.sweep import plan_sweep

from test_sweep import _config

SRC = str(Path(__file__).resolve().parents[2] / "src")
TWO = {"decimation": 0, "parameters": {"brdf.alpha_x": [0.004, 0.03]}}


def _env():
    return dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _toml(tmp_path) -> Path:
    cfg = _config({})
    lines = []
    for section in ("camera", "monitor", "surface", "brdf", "sampling"):
        lines.append(f"[{section}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in cfg[section].items()]
    lines += ["[patterns.fringes]", "widths_px = [50.0, 400.0, 3200.0]", "[sweep]",
              "decimation = 0", "[sweep.parameters]", '"brdf.alpha_x" = [0.004, 0.03]']
    path = tmp_path / "sweep.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _holder(outdir: Path) -> subprocess.Popen:
    code = textwrap.dedent(f"""
        import time
        from pmdsim.run.sweep import claim_sweep
        with claim_sweep({str(outdir)!r}):
            print("held", flush=True)
            time.sleep(120)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, env=_env(),
                            text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_sweep_on_the_same_folder_is_refused_at_once(tmp_path):
    out = tmp_path / "sweep"
    holder = _holder(out)
    try:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pmdsim.cli", "sweep", str(_toml(tmp_path)),
                               "-o", str(out)], env=_env(), capture_output=True, text=True,
                              timeout=120)
        seconds = time.perf_counter() - t0
        assert proc.returncode == 2, proc.stderr
        assert f"being written by process {holder.pid}" in proc.stderr
        # the API refuses too, before creating anything
        with pytest.raises(FileExistsError, match="being written"):
            run_sweep(parse_config(_config(TWO)), out, figures=False)
    finally:
        holder.kill()
        holder.wait()
    assert not out.exists() or list(out.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sweep.lock", "sweep.toml"] or \
        sorted(p.name for p in tmp_path.iterdir()) == ["sweep.toml"]
    print(f"second sweep refused after {seconds:.2f} s (interpreter start included, under load)")


def test_the_cli_checks_the_claim_before_reading_the_configuration(tmp_path, monkeypatch):
    """'At once': the refusal comes before the configuration is read or planned."""
    from typer.testing import CliRunner

    import pmdsim.config as config
    from pmdsim.cli import app

    def never(*args, **kwargs):
        raise AssertionError("the configuration was read before the claim was checked")

    out = tmp_path / "sweep"
    holder = _holder(out)
    try:
        monkeypatch.setattr(config, "load_config", never)
        result = CliRunner().invoke(app, ["sweep", str(tmp_path / "nothing.toml"), "-o", str(out)])
    finally:
        holder.kill()
        holder.wait()
    assert result.exit_code == 2 and "being written" in result.output


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_temporary_stores_are_removed_under_the_claim(tmp_path):
    out = tmp_path / "sweep"
    out.mkdir()
    dead = out / f".{STORE_NAME}.tmp-{_dead_pid()}"
    dead.mkdir()
    (dead / "zarr.json").write_text("{}")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        alive = out / f".{STORE_NAME}.tmp-{live.pid}"
        alive.mkdir()
        with claim_sweep(out):
            assert not dead.exists() and alive.exists()
        assert remove_stale_stores(out) == []
    finally:
        live.kill()
        live.wait()


def test_a_point_whose_write_fails_is_not_done(tmp_path, monkeypatch):
    import pmdsim.run.sweep as sweep_mod

    plan = plan_sweep(parse_config(_config(TWO)))
    store = _open_or_create(plan, tmp_path / "s", overwrite=False)
    p = plan.points[1]
    real = sweep_mod.measure_point(p.config, 0)
    broken = dict(real)
    last = list(broken)[-1]
    broken[last] = np.zeros((7, 7, 7))  # the wrong shape: the write of this variable fails
    monkeypatch.setattr(sweep_mod, "measure_point", lambda cfg, dec: broken)
    with pytest.raises(ValueError):
        compute_point(str(store), p.position, p.config.model_dump_json(), 0, p.index)
    assert not done_mask(store).any()
    monkeypatch.setattr(sweep_mod, "measure_point", lambda cfg, dec: real)
    compute_point(str(store), p.position, p.config.model_dump_json(), 0, p.index)
    assert done_mask(store)[p.position] and done_mask(store).sum() == 1


def test_a_point_killed_mid_write_is_not_done_and_is_recomputed(tmp_path):
    cfg_path = tmp_path / "cfg.json"
    cfg_path.write_text(json.dumps(_config(TWO)))
    out = tmp_path / "killed"
    script = textwrap.dedent(f"""
        import json, os, signal
        import zarr
        from pmdsim.config import parse_config
        from pmdsim.run import sweep

        real = zarr.Array.__setitem__
        writes = [0]

        names = {sorted(_variables())!r}

        def setitem(self, key, value):  # SIGKILL after the first variable of the 2nd point
            if self.path.split("/")[-1] in names:
                writes[0] += 1
            real(self, key, value)
            if writes[0] == len(names) + 1:
                os.kill(os.getpid(), signal.SIGKILL)

        zarr.Array.__setitem__ = setitem
        cfg = parse_config(json.loads(open({str(cfg_path)!r}).read()))
        sweep.run_sweep(cfg, {str(out)!r}, scheduler="synchronous", figures=False)
        """)
    proc = subprocess.run([sys.executable, "-c", script], env=_env(), capture_output=True,
                          timeout=600)
    assert proc.returncode == -9, proc.stderr.decode()[-2000:]
    done = done_mask(out / STORE_NAME)
    assert done.sum() == 1  # the first point; the second was killed half-written
    res = run_sweep(parse_config(_config(TWO)), out, scheduler="synchronous", figures=False)
    assert len(res.computed) == 1 and len(res.skipped) == 1
    assert done_mask(out / STORE_NAME).all()


def _variables():
    from pmdsim.studies.sweep import POINT_VARIABLES

    return POINT_VARIABLES


def test_a_dead_scheduler_address_fails_fast_naming_the_option(tmp_path):
    pytest.importorskip("distributed")
    from typer.testing import CliRunner

    from pmdsim.cli import app

    out = tmp_path / "sweep"
    result = CliRunner().invoke(app, ["sweep", str(_toml(tmp_path)), "-o", str(out),
                                      "--scheduler", "tcp://127.0.0.1:9"])
    assert result.exit_code == 2, result.output
    assert "--scheduler" in result.output and "tcp://127.0.0.1:9" in result.output
    assert not out.exists()
