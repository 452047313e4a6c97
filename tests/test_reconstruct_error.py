"""The reconstruction's numerical error carried linearly (measure/reconstruct_error.py)
against the reconstruction repeated with the moved coordinates (what a run computed
before, and what the linear carry replaces)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from pmdsim.config import load_config, parse_config
from pmdsim.render import Simulation
from pmdsim.run import load_run, run_simulation
from pmdsim.run import reconstruction as recon

EXAMPLES = Path(__file__).parents[1] / "examples"


def _fig3(d):
    # the Fig. 3 set-up (25 deg, tilted monitor, alpha_x != alpha_y) on a small camera
    d["camera"].update(resolution=(96, 80), pixel_pitch_mm=0.0048 * 12)
    d["sampling"].update(n_rays=16)
    d["reconstruct"] = dict(d.get("reconstruct") or {}, spacing_mm=3.0)


def _sphere(d):
    # a curved, turned part (its own frame per point) and a circular aperture
    d["camera"].update(resolution=(64, 48), pixel_pitch_mm=0.03)
    d["sampling"].update(n_rays=16, mode="rule")
    d["variants"] = []
    d["brdf"] = d["variants_brdf"]
    d["reconstruct"]["spacing_mm"] = 1.0


def _run(tmp_path, example, change):
    cfg = load_config(EXAMPLES / example)
    d = cfg.model_dump()
    if example == "turned_sphere.toml":
        d["variants_brdf"] = d["variants"][1]["brdf"]
    change(d)
    d.pop("variants_brdf", None)
    cfg = parse_config(d)
    out = tmp_path / "run"
    run_simulation(cfg, out, diagnostics=False, figures=False)
    return out


@pytest.mark.parametrize("example, change, inside_tol, edge_tol, stat_tol", [
    ("paper_fig3.toml", _fig3, 2e-4, 0.03, 0.02),
    # 3-4 nodes per camera pixel, coordinate errors of up to 12 px (16 nodes on a sphere):
    # the spline and the bilinear carry interpolate between the pixels differently
    ("turned_sphere.toml", _sphere, 2e-2, 0.2, 0.04)])
def test_linear_carry_matches_the_repeated_reconstruction(tmp_path, example, change,
                                                          inside_tol, edge_tol, stat_tol):
    """Per node and per statistic, the linear carry of the coordinates' numerical error
    (:func:`~pmdsim.run.reconstruction.moved_errors`) gives what repeating the whole
    reconstruction with the moved coordinates gives: each node's error more than 4 nodes
    inside the measured area within ``inside_tol`` of the largest, and within ``edge_tol`` at
    its edge (where the repeated reconstruction's cubic spline reads the smoothly filled
    invalid pixels, the bilinear carry only valid ones), the stated errors of RMS, P95 and
    PV within ``stat_tol``; and
    it is linear (twice the coordinate error, twice the change, to 2 %). The run's statistics.json
    states the linear carry's errors."""
    out = _run(tmp_path, example, change)
    stats = json.loads((out / "statistics.json").read_text())["reconstruction"]
    ds = load_run(out)
    cfg = parse_config(json.loads(ds.attrs["config_json"]))
    scene = Simulation.from_config(cfg).scene
    dirs = list(ds["direction"].values)
    coord = {k: np.where(ds["valid"].values[dirs.index(k)],
                         ds["monitor_coord_px"].values[dirs.index(k)], np.nan) for k in "xy"}
    err = {k: ds["coord_deviation_px_error"].values[dirs.index(k)].astype(np.float64)
           for k in "xy"}
    u, v = coord["x"], coord["y"]
    valid = np.isfinite(u) & np.isfinite(v)
    assert np.nanmax(err["x"]) > 0 and np.nanmax(err["y"]) > 0
    rec, base, _ = recon.reconstruct_coords(cfg, scene, u, v, valid)
    lin = recon.moved_errors(cfg, scene, rec, u, v, err["x"], err["y"], valid)
    _, full, _ = recon.reconstruct_coords(cfg, scene, u + np.nan_to_num(err["x"]),
                                          v + np.nan_to_num(err["y"]), valid,
                                          start=rec.height_mm, tables=False)
    lin2 = recon.moved_errors(cfg, scene, rec, u, v, 2 * err["x"], 2 * err["y"], valid)
    for attr in ("height_nm", "slope_x_urad", "slope_y_urad"):
        a = getattr(base, attr)
        e_full = getattr(full, attr) - a
        e_lin = getattr(lin, attr) - a
        ok = np.isfinite(e_full)
        assert np.array_equal(ok, np.isfinite(e_lin)), attr
        scale = np.max(np.abs(e_full[ok]))
        assert scale > 0, attr
        diff = np.abs(e_lin - e_full)
        inside = ok & (ndimage.distance_transform_edt(rec.mask) > 4)
        assert inside.sum() > 0.3 * ok.sum()
        assert diff[inside].max() <= inside_tol * scale, (attr, diff[inside].max(), scale)
        assert diff[ok].max() <= edge_tol * scale, (attr, diff[ok].max(), scale)
        e_lin2 = getattr(lin2, attr) - a
        # (each node's direct slope change is exact, not linearised: 12 px bend it by ~1 %)
        np.testing.assert_allclose(e_lin2[ok], 2 * e_lin[ok], rtol=0, atol=2e-2 * scale)
    s_full, s_lin = copy.deepcopy(base.stats), copy.deepcopy(base.stats)
    recon.add_numerical_error(s_full, base, full)
    recon.add_numerical_error(s_lin, base, lin)
    for key in recon._ERROR_STATS:
        for stat in ("rms_err", "p95_err", "pv_err"):
            assert s_lin[key][stat] == pytest.approx(s_full[key][stat], rel=stat_tol, abs=1e-9), (
                key, stat)
            # the run wrote the linear carry's (of its float64 maps; the store's are
            # float32 rounded to 16 significant bits)
            assert stats[key][stat] == pytest.approx(s_lin[key][stat], rel=1e-4, abs=1e-9)


def test_a_monitor_model_without_a_planar_grid_repeats_the_reconstruction(monkeypatch):
    """moved_reconstruction declines a monitor it cannot continue (None): moved_errors
    then repeats the reconstruction, as the run did before."""
    from pmdsim.measure import reconstruct_error

    class Other:
        def pixel_to_world(self, u, v):
            raise AssertionError("not called")

    rec = type("R", (), {"mask": np.ones((2, 2), bool)})()
    assert reconstruct_error.moved_reconstruction(rec, None, Other(), None, None, None, None,
                                                  None) is None
