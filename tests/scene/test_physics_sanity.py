"""Physics sanity before the work (pmdsim.scene.sanity and the configuration's bounds): a
sensor, display, lens or BRDF that leaves no decodable signal, moves the monitor off the
reference or is impossible is refused naming *that* section and field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from conftest import base_dict, merge
from pmdsim.config import ConfigError, parse_config
from pmdsim.scene import Scene
from pmdsim.studies.physics_checks import check_physics
from pmdsim.scene.sanity import check_sensor
from pmdsim.scene.sensor import Sensor


def _check(**changes):
    cfg = parse_config(merge(base_dict(), changes))
    return check_physics(cfg, Scene.from_config(cfg))


def _field(err) -> str:
    lines = str(err.value).splitlines()
    return (lines[1] if len(lines) > 1 else lines[0]).strip().split(":")[0]


ON = {"enabled": True}
REFUSED = {
    "gain": ({"sensor": ON | {"gain_dn_per_electron": 1e30}}, "sensor.gain_dn_per_electron"),
    "dark_noise": ({"sensor": ON | {"dark_noise_electrons": 1e6}}, "sensor.dark_noise_electrons"),
    "dsnu": ({"sensor": ON | {"dsnu_electrons": 1e9}}, "sensor.dsnu_electrons"),
    "dark_signal": ({"sensor": ON | {"dark_signal_electrons": 20000.0}},
                    "sensor.dark_signal_electrons"),
    "bit_depth": ({"sensor": ON | {"bit_depth": 1}}, "sensor.bit_depth"),
    "falloff_exponent": ({"monitor": {"falloff_exponent": 1e6}}, "monitor.falloff_exponent"),
    "falloff_table": ({"monitor": {"falloff_table": [[0.0, 0.0], [89.0, 0.0]]}},
                      "monitor.falloff_table"),
    "cover_glass": ({"monitor": {"cover_glass_thickness_mm": 1e6}},
                    "monitor.cover_glass_thickness_mm"),
    "flatness": ({"monitor": {"flatness_coefficients_mm": [[1e6]]}},
                 "monitor.flatness_coefficients_mm"),
    "albedo": ({"brdf": {"variation": {"radius_mm": [0.0, 50.0], "rho_s_scale": [1.0, 1e3]}}},
               "brdf.variation.rho_s_scale"),
}


@pytest.mark.parametrize("name", list(REFUSED))
def test_no_signal_is_refused_naming_the_field(name):
    changes, field = REFUSED[name]
    with pytest.raises(ConfigError) as info:
        _check(**changes)
    assert _field(info) == field, str(info.value)


CONFIG_REFUSED = {
    "full_well": ({"sensor": ON | {"full_well_electrons": 1e30}}, "sensor.full_well_electrons"),
    "exposure": ({"sensor": ON | {"exposure_electrons": 1e30}}, "sensor.exposure_electrons"),
    "f_number": ({"camera": {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.2,
                             "focal_length_px": None, "f_number": 1e-6}}, "camera.f_number"),
    "focus": ({"camera": {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.2, "focal_length_px": None,
                          "f_number": 4.0, "focus_distance_mm": 1e-9}},
              "camera.focus_distance_mm"),  # "camera: focus_distance_mm = 1e-09 must ..."
    "widths": ({"patterns": {"fringes": {"widths_px": [50.0, 1e-300, 3200.0]}}},
               "patterns.fringes.widths_px"),
    "sphere": ({"surface": {"__replace__": {"type": "sphere", "radius_mm": 30.0,
                                            "aperture": {"radius_mm": 40.0}}}}, "surface"),
}


@pytest.mark.parametrize("name", list(CONFIG_REFUSED))
def test_impossible_settings_are_config_errors_naming_the_field(name):
    changes, field = CONFIG_REFUSED[name]
    with pytest.raises(ConfigError) as info:
        parse_config(merge(base_dict(), changes))
    msg = str(info.value)
    # a field's own bound names its path; a section's validator names section and field
    assert field in msg or all(part in msg for part in field.split(".")), msg
    if name == "sphere":
        assert "aperture" in msg and "30" in msg


def test_an_aperture_inside_the_sphere_and_an_open_conic_are_accepted():
    ok = {"type": "sphere", "radius_mm": 30.0, "aperture": {"radius_mm": 29.0}}
    parse_config(merge(base_dict(), {"surface": {"__replace__": ok}}))
    hyperbola = {"type": "conic", "radius_mm": 30.0, "conic": -2.0,
                 "aperture": {"radius_mm": 400.0}}  # 1 + k < 0: no edge
    parse_config(merge(base_dict(), {"surface": {"__replace__": hyperbola}}))
    off_axis = {"type": "sphere", "radius_mm": -30.0,
                "aperture": {"radius_mm": 10.0, "centre_mm": [15.0, 6.0]}}  # reaches 26.2 mm
    parse_config(merge(base_dict(), {"surface": {"__replace__": off_axis}}))
    with pytest.raises(ConfigError, match="aperture"):
        parse_config(merge(base_dict(), {"surface": {"__replace__": dict(
            off_axis, aperture={"radius_mm": 10.0, "centre_mm": [18.0, 12.0]})}}))  # 31.6 mm


def test_sane_sensors_and_displays_pass_without_a_note():
    assert _check(sensor=ON | {"dark_noise_electrons": 10.0, "dsnu_electrons": 30.0,
                               "prnu": 0.01, "bit_depth": 8},
                  monitor={"falloff_exponent": 2.0, "cover_glass_thickness_mm": 1.1,
                           "flatness_coefficients_mm": [[0.0, 1e-3], [1e-3, 0.0]]}) == []


def test_the_dsnu_share_matches_the_sensors_own_fixed_pattern():
    """The note's share of clipped pixels against a direct count over the sensor's own DSNU
    draw (its fixed pattern): a pixel is clipped when its dark offset pushes the fringe's
    range [0, E] + mu_d + offset outside [0, full well]."""
    sensor = Sensor(enabled=True, full_well_electrons=10000.0, target_fill=0.5,
                    dark_signal_electrons=500.0, dsnu_electrons=4000.0, seed=3)
    notes = check_sensor(sensor)
    assert len(notes) == 1 and notes[0].startswith("sensor.dsnu_electrons")
    share = float(notes[0].split("pushes ")[1].split(" %")[0]) / 100
    _, off = sensor.fixed_patterns((400, 300))
    lo = sensor.dark_signal_electrons + off
    clipped = np.mean((lo < 0) | (lo + sensor.exposure > sensor.full_well_electrons))
    assert share == pytest.approx(clipped, abs=0.01)
    assert 0.5 < share < 0.99


def test_a_mostly_dark_display_is_noted_with_its_share():
    """cos^m falloff: the lit share (>= 1e-3) against a direct count on a fine grid of
    monitor pixels of the base scene."""
    m = 1000.0  # lit within ~7 deg of the normal: ~7 % of the monitor
    notes = _check(monitor={"falloff_exponent": m})
    assert len(notes) == 1 and notes[0].startswith("monitor.falloff_exponent"), notes
    share = float(notes[0].split("only ")[1].split(" %")[0]) / 100
    cfg = parse_config(base_dict())
    mon = Scene.from_config(cfg).monitor
    u, v = np.meshgrid(np.arange(mon.width) + 0.0, np.arange(mon.height) + 0.0)
    p = mon.pixel_to_world(u.ravel(), v.ravel())
    d = np.asarray(cfg.camera.look_at_mm) - p
    cos = (d @ mon.normal) / np.linalg.norm(d, axis=1)
    assert share == pytest.approx(np.mean(cos**m >= 1e-3), abs=0.02)


def _toml(data: dict, prefix: str = "") -> str:
    import json

    plain = [f"{k} = {json.dumps(v)}" for k, v in data.items() if not isinstance(v, dict)]
    out = ([f"[{prefix}]"] if prefix and plain else []) + plain
    for k, v in data.items():
        if isinstance(v, dict):
            out.append(_toml(v, f"{prefix}.{k}" if prefix else k))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("name", ["gain", "falloff_exponent", "cover_glass"])
def test_simulate_exits_2_naming_the_field_before_the_work(tmp_path, name):
    from pmdsim.cli import app

    changes, field = REFUSED[name]
    cfg = tmp_path / "run.toml"
    cfg.write_text(_toml(merge(base_dict(), changes)))
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["simulate", str(cfg), "-o", str(out)])
    assert result.exit_code == 2, result.output
    assert field in result.output and not out.exists()


def test_texture_refuses_grazing_incidence():
    from pmdsim.cli import app

    for deg in ("90", "95", "-1"):
        result = CliRunner().invoke(app, ["texture", "--feed-um", "10", "--nose-radius-mm", "1",
                                          "--incidence-deg", deg, "--no-figure"])
        assert result.exit_code == 2, result.output
        assert "--incidence-deg" in result.output
    assert not math.isnan(0.0)


@pytest.mark.parametrize("bits", [1, 2, 4])
def test_camera_values_stay_in_the_displays_range(bits):
    """Continuous monitor, gamma 2.2, a coarsely quantised drive: the 16-harmonic series
    rings; every camera value must stay within [black, white] x the weight on the monitor
    (the range of a weighted mean of displayed luminances), so never negative."""
    from pmdsim.render import Simulation

    cfg = parse_config(merge(base_dict(), {"monitor": {"pixel_model": "continuous",
                                                       "gamma": 2.2, "bit_depth": bits,
                                                       "black_level": 0.0}}))
    fr = Simulation.from_config(cfg).render_fringes(widths=[20.0], shifts=4)
    img = fr.images.astype(np.float64)
    ok = np.isfinite(img)
    assert ok.any()
    hit = np.broadcast_to(fr.f_hit, img.shape)[ok]
    assert img[ok].min() >= 0.0
    assert np.all(img[ok] <= hit * cfg.monitor.white_level * (1 + 1e-6) + 1e-12)


def _values():
    return st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                     st.sampled_from([0.0, 1e-300, 1e-9, 0.5, 1.0, 2.0, 1e6, 1e30, -1.0]),
                     st.integers(-5, 70000))


def _sections():
    sensor = st.fixed_dictionaries({"enabled": st.just(True)}, optional={
        k: _values() for k in ("full_well_electrons", "dark_noise_electrons",
                               "dark_signal_electrons", "dsnu_electrons", "prnu",
                               "gain_dn_per_electron", "bit_depth", "offset_dn",
                               "exposure_electrons", "target_fill")})
    monitor = st.fixed_dictionaries({}, optional={
        "falloff_exponent": _values(), "cover_glass_thickness_mm": _values(),
        "cover_glass_index": _values(),
        "flatness_coefficients_mm": st.lists(st.lists(_values(), min_size=2, max_size=2),
                                             min_size=2, max_size=2),
        "falloff_table": st.lists(st.tuples(st.floats(0, 89.9), _values()), max_size=4)
                           .map(lambda rows: sorted(rows))})
    return st.fixed_dictionaries({}, optional={"sensor": sensor, "monitor": monitor})


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(changes=_sections())
def test_any_sensor_or_display_is_a_field_named_error_or_checked(changes):
    """Extreme, non-finite and out-of-range sensor and display settings: a configuration
    error naming a field, a physics refusal naming the section's field, or notes (each
    naming its field); no other exception."""
    try:
        cfg = parse_config(merge(base_dict(), changes))
    except ConfigError as err:
        assert str(err).splitlines()[1].strip().split(":")[0].split(".")[0] in changes
        return
    try:
        notes = check_physics(cfg, Scene.from_config(cfg))
    except ConfigError as err:
        field = _field(type("I", (), {"value": err})())
        assert field.split(".")[0] in ("sensor", "monitor"), str(err)
        return
    assert all(n.split(".")[0] in ("sensor", "monitor") for n in notes), notes


# ----------------------------------------------------------------------------- albedo override
def test_an_albedo_above_one_is_refused_unless_the_override_says_so():
    """rho_s x the largest rho_s_scale (0.4 x 1e3 = 400) and a Fresnel factor above 1 are
    refused naming the field and the override; with diagnostics.allow_albedo_above_one
    the same settings give one note naming the field, the albedo and the override."""
    scale = {"brdf": {"variation": {"radius_mm": [0.0, 50.0], "rho_s_scale": [1.0, 1e3]}}}
    with pytest.raises(ConfigError) as info:
        _check(**scale)
    assert _field(info) == "brdf.variation.rho_s_scale"
    assert "400" in str(info.value) and "allow_albedo_above_one" in str(info.value)
    notes = _check(**merge(scale, {"diagnostics": {"allow_albedo_above_one": True}}))
    assert len(notes) == 1 and notes[0].startswith("brdf.variation.rho_s_scale"), notes
    assert "400" in notes[0] and "allow_albedo_above_one" in notes[0]
    # a slope density's Fresnel factor above 1 (its rho_s has no upper bound of its own)
    dens = {"brdf": {"__replace__": {"model": "slope_density", "density": "gaussian",
                                     "alpha_x": 0.02, "alpha_y": 0.01, "rho_s": 5.0}}}
    with pytest.raises(ConfigError) as info:
        _check(**dens)
    assert _field(info) == "brdf.rho_s" and "allow_albedo_above_one" in str(info.value)
    assert _check(**merge(dens, {"diagnostics": {"allow_albedo_above_one": True}}))[0] \
        .startswith("brdf.rho_s")
    # the bound itself: exactly 1 passes without a note, just above it does not
    assert _check(brdf={"variation": {"radius_mm": [0.0, 50.0],
                                      "rho_s_scale": [1.0, 2.5]}}) == []
    with pytest.raises(ConfigError):
        _check(brdf={"variation": {"radius_mm": [0.0, 50.0], "rho_s_scale": [1.0, 2.5001]}})


# ----------------------------------------------------------------------------- every command
def _sweep_toml(tmp_path, values) -> Path:
    from test_sweep import _config

    data = _config({})
    data.pop("sweep")
    data["sensor"] = {"enabled": True}
    path = tmp_path / "sweep.toml"
    path.write_text(_toml(data) + "[sweep]\ndecimation = 0\n[sweep.parameters]\n"
                    f'"sensor.gain_dn_per_electron" = {values!r}\n')
    return path


def test_sweep_checks_every_point_before_anything_is_created(tmp_path):
    """The second point's gain saturates every pixel: refused before the store (or the
    folder) exists, naming the point, its value and the field; exit 2."""
    from pmdsim.cli import app

    out = tmp_path / "sweep"
    result = CliRunner().invoke(app, ["sweep", str(_sweep_toml(tmp_path, [0.5, 1e30])),
                                      "-o", str(out), "--no-figures"])
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.split())
    assert "sweep point 1 (sensor.gain_dn_per_electron = 1e+30)" in text, text
    assert "sensor.gain_dn_per_electron: the mean fringe level" in text
    assert not out.exists()


def test_the_sweep_checks_each_distinct_point_once_and_labels_its_notes():
    from pmdsim.studies import physics_checks

    cfgs = [parse_config(merge(base_dict(), {"monitor": {"falloff_exponent": 1000.0},
                                             "sampling": {"seed": s}})) for s in range(3)]
    calls = []
    real = physics_checks.check_physics
    try:
        physics_checks.check_physics = lambda cfg, scene=None: calls.append(cfg) or real(cfg)
        notes = physics_checks.check_each(cfgs, ["a", "b", "c"])
    finally:
        physics_checks.check_physics = real
    assert len(calls) == 1 and len(notes) == 1 and notes[0].startswith("a: monitor.falloff")


def test_converge_refuses_a_sensor_without_signal_before_the_work(tmp_path):
    from pmdsim.cli import app

    changes, field = REFUSED["dark_noise"]
    cfg = tmp_path / "run.toml"
    cfg.write_text(_toml(merge(base_dict(), changes)))
    out = tmp_path / "conv"
    result = CliRunner().invoke(app, ["converge", str(cfg), "-o", str(out), "--camera", "8x6",
                                      "--n-values", "4", "--theta", "1"])
    assert result.exit_code == 2, result.output
    assert field in result.output and not out.exists()


def test_fit_refuses_a_display_without_signal_before_reading_the_images(tmp_path):
    """The physics check comes before the images are read: the error names the monitor's
    field, not the missing image file."""
    from pmdsim.cli import app

    changes, field = REFUSED["falloff_table"]
    cfg = tmp_path / "fit.toml"
    cfg.write_text(_toml(merge(base_dict(), changes)))
    out = tmp_path / "fit"
    result = CliRunner().invoke(app, ["fit", str(cfg), str(tmp_path / "missing.tif"),
                                      "-o", str(out), "--no-figure"])
    assert result.exit_code == 2, result.output
    assert field in result.output and "missing.tif" not in result.output
    assert not out.exists()


def _strict_json(path):
    import json

    def refuse(name):
        raise AssertionError(f"{path.name} holds {name}")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_a_coarse_precompensated_display_gives_clipped_images_and_strict_statistics(tmp_path):
    """Issue 21's case through simulate: a continuous monitor, gamma 2.2 pre-compensated,
    a 2-bit drive. The camera values in run.zarr stay >= 0 and statistics.json (and the
    manifest) hold no NaN/Infinity: a strict parser reads them."""
    from pmdsim import load_run
    from pmdsim.cli import app

    cfg = tmp_path / "run.toml"
    cfg.write_text(_toml(merge(base_dict(), {
        "camera": {"resolution": [16, 12], "focal_length_px": 32.0},
        "monitor": {"pixel_model": "continuous", "gamma": 2.2, "bit_depth": 2,
                    "precompensate_gamma": True},
        "sampling": {"n_rays": 8},
        "patterns": {"fringes": {"widths_px": [50.0, 400.0]}}})))
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert result.exit_code == 0, result.output
    stats = _strict_json(out / "statistics.json")
    assert stats["directions"]["x"]["pixels"]["valid"] > 0
    for f in out.glob("*.json"):
        _strict_json(f)
    img = np.asarray(load_run(out)["fringes"].values, np.float64)
    assert np.nanmin(img) >= 0.0


def test_result_json_is_strict():
    """NaN and infinities become null, NumPy scalars plain numbers, nested anywhere."""
    import json

    from pmdsim.store.tables import json_safe

    data = {"a": float("nan"), "b": [np.float32(1.5), np.inf, {"c": -np.inf}],
            "d": np.int64(3), "e": np.bool_(True), "f": (1, "x")}
    text = json.dumps(json_safe(data), allow_nan=False)
    assert json.loads(text) == {"a": None, "b": [1.5, None, {"c": None}], "d": 3, "e": True,
                                "f": [1, "x"]}
