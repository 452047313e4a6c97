"""Parameter sweeps: validation before anything runs, resume after a kill, scheduler
independence, per-point reproducibility (pmdsim.studies.sweep, pmdsim.run.sweep)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from pmdsim.config import ConfigError, parse_config
from pmdsim.run.sweep import done_mask, load_sweep, run_sweep
from pmdsim.studies.sweep import measure_point, plan_sweep, point_seed

SRC = str(Path(__file__).resolve().parents[2] / "src")


def _config(sweep: dict) -> dict:
    """A small Fig. 3-like set-up (48 x 40 camera seeing the whole plate), random sampling so
    that the per-point seeds matter."""
    return {
        "name": "sweep-test",
        "camera": {"resolution": [48, 40], "pixel_pitch_mm": 0.128, "focal_length_mm": 50.0,
                   "position_mm": [-845.236523481399, 0.0, 1812.6155740733],
                   "look_at_mm": [0.0, 0.0, 0.0]},
        "monitor": {"resolution": [1920, 1080], "pixel_pitch_mm": 0.25,
                    "centre_mm": [253.57095704442, 0.0, 543.78467222199],
                    "look_at_mm": [0.0, 0.0, 0.0], "pixel_model": "continuous"},
        "surface": {"size_mm": [300.0, 200.0]},
        "brdf": {"model": "ward", "alpha_x": 0.01, "alpha_y": 0.002},
        # the paper's estimator named: a sweep's default is the radiometric one, whose 16
        # random rays over the whole lobe leave the widest lobe's modulation at its noise
        "sampling": {"n_rays": 16, "mode": "random", "seed": 3, "estimator": "paper"},
        "patterns": {"fringes": {"widths_px": [50.0, 400.0, 3200.0]}},
        "compute": {"tile_rows": 16},
        "sweep": sweep,
    }


SWEEP = {"decimation": 4, "parameters": {"brdf.alpha_x": [0.004, 0.01, 0.03],
                                         "patterns.fringes.widths_px.0": [50.0, 100.0]}}
VARIABLES = ("deviation_stats", "modulation_median", "modulation_ratio_median",
             "phase_deviation", "slope_deviation_urad", "modulation", "done", "point_seed",
             "point_index")


def _arrays(path) -> dict:
    ds = load_sweep(path)
    return {k: ds[k].values for k in VARIABLES}


def _assert_identical(a: dict, b: dict) -> None:
    for k in VARIABLES:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        assert a[k].tobytes() == b[k].tobytes(), f"{k} differs"


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "full"
    res = run_sweep(parse_config(_config(SWEEP)), out, scheduler="threads", num_workers=2,
                    figures=False)
    assert res.computed == tuple(range(6)) and res.skipped == ()
    return out


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize("path, says", [
    ("brdf.alpha_z", "'alpha_z' is not a field of brdf"),
    ("sampling.nrays", "'nrays' is not a field of sampling"),
    ("patterns.fringes.widths_px.3", "give an index 0..2"),
    ("patterns.dots.size_px", "patterns.dots is not set in the base configuration"),
    ("camera_resolution", "not a field of the top level"),
])
def test_bad_field_is_a_clear_error_before_anything_runs(tmp_path, path, says):
    cfg = parse_config(_config({"parameters": {path: [1, 2]}}))
    out = tmp_path / "never"
    with pytest.raises(ConfigError) as err:
        run_sweep(cfg, out)
    assert path in str(err.value) and says in str(err.value)
    assert not out.exists()


def test_bad_value_names_the_point_and_field(tmp_path):
    cfg = parse_config(_config({"parameters": {"brdf.alpha_x": [0.01, -1.0]}}))
    with pytest.raises(ConfigError, match=r"sweep point 1 \(brdf.alpha_x = -1.0\)"
                                          r"[\s\S]*brdf.alpha_x: Input should be greater than 0"):
        run_sweep(cfg, tmp_path / "never")
    assert not (tmp_path / "never").exists()


def test_undecodable_point_is_an_error_before_anything_runs():
    cfg = parse_config(_config({"parameters": {"patterns.fringes.widths_px.2": [3200.0, 500.0]}}))
    with pytest.raises(ConfigError, match=r"sweep point 1 .*widths_px"):
        plan_sweep(cfg)


def test_designs_and_seeds():
    grid = plan_sweep(parse_config(_config(SWEEP)))
    assert grid.dims == ("brdf.alpha_x", "patterns.fringes.widths_px.0") and grid.shape == (3, 2)
    assert [p.position for p in grid.points][:3] == [(0, 0), (0, 1), (1, 0)]
    assert grid.points[3].config.brdf.alpha_x == 0.01
    assert grid.points[3].config.patterns.fringes.widths_px == (100.0, 400.0, 3200.0)
    # Seeds keyed by (sampling.seed, point index), independent of the rest of the design.
    assert [p.config.sampling.seed for p in grid.points] == [point_seed(3, i) for i in range(6)]
    assert len({p.config.sampling.seed for p in grid.points}) == 6
    crn = plan_sweep(parse_config(_config(dict(SWEEP, common_random_numbers=True))))
    assert {p.config.sampling.seed for p in crn.points} == {3}
    # The camera's noise is keyed the same way when the sensor is on.
    noisy = plan_sweep(parse_config(dict(_config(SWEEP), sensor={"enabled": True, "seed": 5})))
    assert [p.config.sensor.seed for p in noisy.points] == [point_seed(5, i) for i in range(6)]

    zipped = plan_sweep(parse_config(_config({"design": "zip", "parameters": {
        "brdf.alpha_x": [0.004, 0.01], "brdf.alpha_y": [0.001, 0.003]}})))
    assert zipped.dims == ("point",) and zipped.shape == (2,)
    assert [p.config.brdf.alphas for p in zipped.points] == [(0.004, 0.001), (0.01, 0.003)]

    rnd = {"design": "random", "points": 50, "seed": 7, "parameters": {
        "brdf.alpha_x": {"min": 1e-3, "max": 1e-1, "scale": "log"},
        "sampling.theta_max_deg": [0.5, 1.0]}}
    a = plan_sweep(parse_config(_config(rnd)))
    b = plan_sweep(parse_config(_config(rnd)))
    ax = np.array([p.config.brdf.alpha_x for p in a.points])
    assert np.array_equal(ax, [p.config.brdf.alpha_x for p in b.points])
    assert ax.min() >= 1e-3 and ax.max() <= 1e-1
    assert (ax < 1e-2).sum() > 10 and (ax > 1e-2).sum() > 10  # log-uniform: half below 1e-2
    assert {p.config.sampling.theta_max_deg for p in a.points} == {0.5, 1.0}


def test_zip_lengths_and_ranges_checked():
    with pytest.raises(ConfigError, match="equal length"):
        parse_config(_config({"design": "zip", "parameters": {"brdf.alpha_x": [0.01, 0.02],
                                                              "brdf.alpha_y": [0.001]}}))
    with pytest.raises(ConfigError, match="needs design = 'random'"):
        parse_config(_config({"parameters": {"brdf.alpha_x": {"min": 0.01, "max": 0.02}}}))


def test_dotted_toml_keys_read_as_paths():
    import tomllib

    data = tomllib.loads(textwrap.dedent("""
        [sweep.parameters]
        brdf.alpha_x = [0.01, 0.02]
        "patterns.fringes.widths_px.0" = [50.0]
        """))
    cfg = parse_config(dict(_config({}), sweep=data["sweep"]))
    assert list(cfg.sweep.parameters) == ["brdf.alpha_x", "patterns.fringes.widths_px.0"]


# ----------------------------------------------------------------------------- running
def test_point_recomputes_bit_identically(uninterrupted):
    plan = plan_sweep(parse_config(_config(SWEEP)))
    p = plan.points[4]
    alone = measure_point(p.config, SWEEP["decimation"])
    ds = load_sweep(uninterrupted)
    for k, v in alone.items():
        stored = ds[k].values[p.position]
        assert stored.tobytes() == v.tobytes(), k
    assert ds["done"].values.all()
    # The sweep is physical: more scatter along x loses X-fringe modulation.
    mod = ds["modulation_median"].sel(direction="x", width=0).values
    assert np.all(np.diff(mod, axis=0) < 0)


def test_interrupted_sweep_resumes_only_unfinished_points(tmp_path, uninterrupted):
    cfg_path = tmp_path / "cfg.json"
    cfg_path.write_text(json.dumps(_config(SWEEP)))
    out = tmp_path / "resumed"
    script = textwrap.dedent(f"""
        import json, os, signal
        from pmdsim.config import parse_config
        from pmdsim.run.sweep import run_sweep

        def progress(done, total):
            if done == 2:  # killed abruptly, as by the OOM killer or a pulled plug
                os.kill(os.getpid(), signal.SIGKILL)

        cfg = parse_config(json.loads(open({str(cfg_path)!r}).read()))
        run_sweep(cfg, {str(out)!r}, scheduler="synchronous", progress=progress,
                  figures=False)
        """)
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          timeout=600)
    assert proc.returncode == -9, proc.stderr.decode()[-2000:]
    done = done_mask(out / "sweep.zarr")
    assert done.sum() == 2
    res = run_sweep(parse_config(_config(SWEEP)), out, scheduler="threads", num_workers=2,
                    figures=False)
    unfinished = {int(i) for i in load_sweep(out)["point_index"].values[~done]}
    assert set(res.computed) == unfinished and len(res.skipped) == 2
    _assert_identical(_arrays(out), _arrays(uninterrupted))
    again = run_sweep(parse_config(_config(SWEEP)), out, figures=False)
    assert again.computed == () and len(again.skipped) == 6


def test_threads_and_distributed_processes_agree(tmp_path, uninterrupted):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "distributed"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        res = run_sweep(parse_config(_config(SWEEP)), out, client=client, figures=False)
        workers = set(client.run(os.getpid).values())
    assert res.computed == tuple(range(6)) and len(workers) == 2 and os.getpid() not in workers
    _assert_identical(_arrays(out), _arrays(uninterrupted))


def test_a_different_sweep_in_the_same_folder_is_refused(tmp_path, uninterrupted):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(uninterrupted, out)
    other = dict(SWEEP, parameters={"brdf.alpha_x": [0.004, 0.02]})
    with pytest.raises(FileExistsError, match="different sweep"):
        run_sweep(parse_config(_config(other)), out)
    assert done_mask(out / "sweep.zarr").all()


def test_cli_sweep_writes_store_table_and_figures_and_refuses_bad_fields(tmp_path):
    import tomllib  # noqa: F401  (the CLI reads TOML)

    from typer.testing import CliRunner

    from pmdsim.cli import app

    def toml(sweep_params: str) -> Path:
        cfg = _config({})
        lines = []
        for section in ("camera", "monitor", "surface", "brdf", "sampling"):
            lines.append(f"[{section}]")
            lines += [f"{k} = {json.dumps(v)}" for k, v in cfg[section].items()]
        lines += ["[patterns.fringes]", "widths_px = [50.0, 400.0, 3200.0]",
                  "[sweep]", "decimation = 0", "[sweep.parameters]", sweep_params]
        path = tmp_path / f"cfg{len(list(tmp_path.iterdir()))}.toml"
        path.write_text("\n".join(lines) + "\n")
        return path

    runner = CliRunner()
    bad = runner.invoke(app, ["sweep", str(toml('"brdf.alpha_q" = [0.01]')), "-o",
                              str(tmp_path / "bad")])
    assert bad.exit_code == 2 and "'alpha_q' is not a field of brdf" in bad.output
    assert not (tmp_path / "bad").exists()
    ok = runner.invoke(app, ["sweep", str(toml('"brdf.alpha_x" = [0.004, 0.01]')), "-o",
                             str(tmp_path / "ok"), "--scheduler", "synchronous"])
    assert ok.exit_code == 0, ok.output
    assert "computed 2 points, 0 were already done" in ok.output
    for f in ("sweep.zarr/zarr.json", "points.csv", "config.json", "figures/phase_rms.png",
              "figures/slope_rms.png", "figures/modulation_ratio.png"):
        assert (tmp_path / "ok" / f).is_file(), f
    rows = (tmp_path / "ok" / "points.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("point,brdf.alpha_x,done,x_phase_rms_mrad")
    assert "phase_deviation" not in load_sweep(tmp_path / "ok")  # decimation 0: no maps
