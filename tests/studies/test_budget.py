"""Error budget: each effect alone against its closed form, the surface apart from the
system, the command line, and the example configuration."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pmdsim.cli import app
from pmdsim.config import load_config, parse_config
from pmdsim.measure.decode import DecodeFlag, decode_sequence
from pmdsim.scene.sensor import Sensor
from pmdsim.studies.budget import EFFECTS, budget, ideal_config

from conftest import base_dict, merge

ROOT = Path(__file__).resolve().parents[2]


def _cfg(**changes):
    d = merge(base_dict(), {
        "patterns": {"fringes": {"widths_px": [24.0, 200.0], "shifts": 4}},
        "monitor": {"gamma": 2.2, "bit_depth": 8, "cover_glass_thickness_mm": 1.5,
                    "pixel_model": "nearest"},
        "camera": {"subpixels": 2},
        "sensor": {"enabled": True, "exposure_electrons": 20000.0, "full_well_electrons": 30000.0,
                   "dark_noise_electrons": 5.0},
        "sampling": {"n_rays": 24},
        "reconstruct": {"spacing_mm": 2.5},
    })
    return parse_config(merge(d, changes))


@pytest.fixture(scope="module")
def result():
    return budget(_cfg())


@pytest.fixture(scope="module")
def rows(result):
    return result.rows


def _get(rows, effect, direction):
    return next(r for r in rows if r["effect"] == effect and r["direction"] == direction)


def test_rows_and_parts(rows):
    effects = {r["effect"] for r in rows}
    assert {"ideal", "monitor_pixels", "footprint", "display_response", "cover_glass", "sensor",
            "all_system", "surface_ideal", "surface"} <= effects
    assert "defocus" not in effects and "flatness" not in effects  # not in the config
    assert {r["part"] for r in rows if r["effect"].startswith("surface")} == {"surface"}
    for r in rows:
        assert r["n_valid"] > 100
        for q in ("mrad", "px", "mm", "urad"):
            assert math.isfinite(r[f"rms_{q}"]) and r[f"p95_{q}"] >= 0


def test_effects_alone_match_closed_forms(rows):
    cfg = _cfg()
    # the ideal system decodes the exact point
    for d in ("x", "y"):
        assert _get(rows, "ideal", d)["rms_px"] < 1e-5
        # one ray per pixel on a nearest monitor: the staircase, 1/sqrt(12) px RMS
        assert _get(rows, "monitor_pixels", d)["rms_px"] == pytest.approx(1 / math.sqrt(12), rel=0.2)
        # unit conversions of one row: px -> mm -> mrad
        r = _get(rows, "sensor", d)
        assert r["rms_mm"] == pytest.approx(r["rms_px"] * cfg.monitor.pixel_pitch_mm, rel=1e-9)
        assert r["rms_mrad"] == pytest.approx(r["rms_px"] * 2 * math.pi / 24.0 * 1e3, rel=1e-9)
    # sensor noise alone: sqrt(2 / K) sigma_I / B (finest width), mean over the pixels' levels
    s = Sensor.from_config(cfg.sensor)
    e = 20000.0  # brightest value (1.0) of the mirror's fringes
    sigma = s.gain * np.sqrt(5.0**2 + 0.5 * e)  # shot noise at the mean level 0.5
    b = s.gain * 0.5 * e
    phase = math.sqrt(2 / 4) * sigma / b
    for d in ("x", "y"):
        assert _get(rows, "sensor", d)["rms_mrad"] == pytest.approx(phase * 1e3, rel=0.15)


def test_surface_is_reported_apart_from_the_system(rows):
    for d in ("x", "y"):
        s_ideal = _get(rows, "surface_ideal", d)["rms_px"]
        # the Ward lobe biases the decoded point: the wide lobe (alpha_x 0.025) more than the
        # narrow one (alpha_y 0.002; converged rule sampling, no sampling noise on top)
        assert s_ideal > (0.01 if d == "x" else 0.003)
        assert _get(rows, "ideal", d)["rms_px"] < s_ideal / 100


def test_ideal_config_switches_everything_off():
    ideal = ideal_config(_cfg(camera={"f_number": 4.0, "focal_length_mm": 20.0}))
    assert not any(e.present(ideal) and e.name != "monitor_pixels" for e in EFFECTS)
    assert ideal.monitor.pixel_model == "continuous" and not ideal.sensor.enabled


def test_saturated_pixels_are_flagged():
    phi = np.linspace(-3, 3, 64).reshape(8, 8)
    d = 2 * np.pi * np.arange(4) / 4
    frames = (0.5 + 0.5 * np.cos(phi[None] + d[:, None, None]))[None] * 1000.0
    frames[0, 1, 3, 3] = 4095
    res = decode_sequence(frames, [100.0], 4, 100.0, saturation_level=4095)
    assert res.flags[3, 3] & DecodeFlag.SATURATED
    assert not res.valid[3, 3] and res.valid.sum() == 63


def test_cli_budget(tmp_path):
    d = merge(base_dict(), {"patterns": {"fringes": {"widths_px": [24.0, 200.0]}},
                            "monitor": {"cover_glass_thickness_mm": 1.0},
                            "brdf": {"__replace__": {"model": "mirror"}}})
    cfg_path = tmp_path / "b.toml"
    _write_toml(cfg_path, d)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["budget", str(cfg_path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "cover glass" in res.output and "all system effects" in res.output
    for f in ("budget.csv", "budget.json", "budget.png", "areal.csv", "budget_psd.png"):
        assert (out / f).is_file()
    rows = json.loads((out / "budget.json").read_text())["rows"]
    assert not any(r["part"] == "surface" for r in rows)  # a mirror has no surface part
    res = CliRunner().invoke(app, ["budget", str(cfg_path), "-o", str(out)])
    assert res.exit_code == 2 and "exists" in res.output


def test_realistic_example_runs():
    cfg = load_config(ROOT / "examples" / "realistic_system.toml")
    d = cfg.model_dump()
    d["camera"]["resolution"] = (24, 20)
    res = budget(cfg.model_validate(d))
    effects = {r["effect"] for r in res.rows}
    assert {e.name for e in EFFECTS} <= effects  # the example switches every effect on
    assert {"surface", "surface_ideal", "all_system"} <= effects
    assert {r["effect"] for r in res.height_rows} >= effects | {"camera_position_mm", "calibration_total"}


def test_slopes_across_the_plane_are_the_3d_conversion(rows):
    """The budget's urad are the exact 3-D conversion (as simulate's), not d / (2 D): the
    base scene's plane of incidence is y-z, so X fringes measure across it, where the
    small-angle formula is cos(theta_i) too small."""
    from pmdsim.measure.reconstruct import slope_deviation_3d
    from pmdsim.studies.budget import decode_config, ground_truth, mirror, with_effects

    cfg = _cfg()
    truth = ground_truth(cfg)
    dec = decode_config(mirror(with_effects(cfg, ["cover_glass"])))
    geo, sg = truth.geometry, truth.slope_geometry
    for d in ("x", "y"):
        ok = dec.valid[d] & np.isfinite(truth.coord[d])
        dev = dec.coord[d] - truth.coord[d]
        u0, v0 = geo.specular_u, geo.specular_v
        u1, v1 = (u0 + dev, v0) if d == "x" else (u0, v0 + dev)
        with np.errstate(invalid="ignore"):
            s3 = slope_deviation_3d(sg.points_mm, sg.camera_position, sg.monitor, u0, v0, u1, v1) * 1e6
        m = ok & np.isfinite(s3)
        expect = float(np.sqrt(np.mean(s3[m] ** 2)))
        row = _get(rows, "cover_glass", d)
        assert row["rms_urad"] == pytest.approx(expect, rel=1e-6)
        small = float(np.sqrt(np.mean((dev[m] * cfg.monitor.pixel_pitch_mm / (2 * truth.distance_mm[m])) ** 2))) * 1e6
        if d == "x":  # across the plane: 1/cos(theta_i) above the small-angle value (~25 deg)
            assert 1.05 < row["rms_urad"] / small < 1.15
        else:  # in the plane the two agree
            assert row["rms_urad"] / small == pytest.approx(1.0, abs=0.02)


def test_height_rows_in_nm_with_calibration(result):
    h = {r["effect"]: r for r in result.height_rows}
    assert h["ideal"]["height_rms_nm"] < 5 and h["ideal"]["slope_rms_x_urad"] < 5  # the chain's floor
    for name in ("monitor_pixels", "sensor", "all_system", "surface_ideal", "surface"):
        r = h[name]
        assert r["height_rms_nm"] > 10 * h["ideal"]["height_rms_nm"]
        assert r["height_pv_nm"] >= r["height_p95_nm"] >= 0 and r["n_nodes"] > 50
        assert len(r["zernike_noll_nm"]) == 37 and len(r["zernike_fringe_nm"]) == 37
    calib = [r for r in result.height_rows if r["part"] == "calibration"]
    assert {r["effect"] for r in calib} >= {"camera_position_mm", "camera_orientation_deg",
                                             "focal_length_rel", "principal_point_px", "distortion_k1",
                                             "monitor_position_mm", "monitor_orientation_deg",
                                             "monitor_pitch_rel", "surface_distance_mm",
                                             "calibration_total"}
    tot = h["calibration_total"]
    parts = [r for r in calib if r["effect"] != "calibration_total"]
    assert tot["height_rms_nm"] == pytest.approx(math.sqrt(sum(r["height_rms_nm"] ** 2 for r in parts)))
    assert len(h["camera_position_mm"]["components"]) == 3
    assert "sensitivity x uncertainty" in h["camera_position_mm"]["how"]
    assert result.settings["removed"] == "piston removed"


def test_height_rows_carry_areal_parameters_and_psds(result):
    """Every height row with maps states the ISO 25178 parameters and PSDs of its height and
    slope errors: Sq is the row's height RMS (the same map), and for the surface rows Sq's
    numerical error is the row's RMS error (the same rule); the mirror's rows state their
    reconstruction solver's floor (> 0, at most the floor: a constant node error); the
    bands' RMS add up to the window-weighted mean square; the text table shows them."""
    from pmdsim.report.budget import budget_text
    from pmdsim.studies.budget_areal import areal_rows

    with_maps = [r for r in result.height_rows if r["effect"] != "calibration_total"
                 and r["part"] != "calibration" and not r["effect"].startswith("numerical")]
    assert with_maps
    for r in with_maps:
        ar = r["areal"]
        assert set(ar) == {"height_error_nm", "slope_error_x_urad", "slope_error_y_urad"}
        h = ar["height_error_nm"]
        assert h["sq"] == pytest.approx(r["height_rms_nm"], rel=1e-9)
        assert h["sz"] == pytest.approx(r["height_pv_nm"], rel=1e-9)
        assert h["n"] == r["n_nodes"] and h["unit"] == "nm" and h["sdq"] > 0
        psd = h["psd"]
        assert sum(v * v for v in psd["band_rms"].values()) == pytest.approx(psd["mean_square"])
        assert len(psd["radial"]) == len(psd["frequency_per_mm"]) > 5
        if r["part"] == "surface":
            assert h["sq_err"] == pytest.approx(r["height_rms_nm_err"], rel=1e-9)
            assert all(v > 0 for v in psd["band_rms_err"].values())
            assert len(psd["radial_err"]) == len(psd["radial"])
        else:  # the mirror's exact render: the reconstruction solvers' floors alone
            assert 0 < h["sq_err"] <= r["solver_floor_nm"] * (1 + 1e-9)
            assert h["sq_err"] == pytest.approx(r["height_rms_nm_err"], rel=1e-9)
            assert r["height_pv_nm_err"] == pytest.approx(2 * r["solver_floor_nm"], rel=1e-6)
    comp = next(r for r in result.height_rows if r["effect"] == "camera_position_mm")
    assert comp["components"][0]["areal"]["height_error_nm"]["sq"] == pytest.approx(
        comp["components"][0]["height_rms_nm"], rel=1e-9)
    table = areal_rows(result.height_rows)
    assert {(t["effect"], t["map"]) for t in table} >= {("surface", "height_error_nm"),
                                                         ("ideal", "slope_error_y_urad")}
    assert "band-limited RMS" in budget_text(result.rows, result.height_rows, result.settings)


def _write_toml(path: Path, data: dict) -> None:
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    lines = []
    def section(prefix, d):
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
        if prefix:
            lines.append(f"[{prefix}]")
        lines.extend(f"{k} = {val(v)}" for k, v in scalars.items())
        for k, v in d.items():
            if isinstance(v, dict):
                section(f"{prefix}.{k}" if prefix else k, v)
    section("", data)
    path.write_text("\n".join(lines) + "\n")


def test_footprint_truth():
    """With the footprint average as the truth, sub-pixels on a continuous monitor give the
    same (near-zero) system error as with the centre ray on a flat mirror (they differ by
    < 1e-4 px, docs/system.md); a bad choice is an error."""
    cfg = _cfg(monitor={"pixel_model": "continuous", "gamma": 1.0, "bit_depth": None,
                        "cover_glass_thickness_mm": 0.0}, sensor={"enabled": False})
    rows = budget(cfg.model_copy(update={"budget": cfg.budget.model_copy(update={"reconstruct": False})}),
                  truth="footprint").rows
    for d in ("x", "y"):
        assert _get(rows, "footprint", d)["rms_px"] < 1e-3
    with pytest.raises(ValueError, match="truth"):
        budget(cfg, truth="middle")
