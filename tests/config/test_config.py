"""Configuration: valid configs build the scene they describe; every bad config fails with
a :class:`ConfigError` whose message names the offending field by its dotted path."""

from __future__ import annotations

import math

import numpy as np
import pydantic
import pytest

from conftest import base_dict, make_config, merge
from pmdsim.config import ConfigError, RunConfig, load_config, parse_config
from pmdsim.scene import Scene

BASE_TOML = """
name = "toml-scene"
[camera]
resolution = [40, 32]
focal_length_mm = 16.0
pixel_pitch_mm = 0.2
position_mm = [0.0, -126.8, 271.9]
look_at_mm = [0.0, 0.0, 0.0]
[monitor]
resolution = [200, 120]
pixel_pitch_mm = 1.0
centre_mm = [0.0, 84.5, 181.3]
look_at_mm = [0.0, 0.0, 0.0]
[surface]
size_mm = [100.0, 80.0]
[brdf]
model = "ward"
alpha_x = 0.025
alpha_y = 0.002
"""


def error_of(changes) -> str:
    with pytest.raises(ConfigError) as info:
        parse_config(merge(base_dict(), changes))
    return str(info.value)


# --------------------------------------------------------------------------- valid configs


def test_base_config_builds_the_scene_it_describes():
    cfg = make_config()
    scene = Scene.from_config(cfg)
    assert (scene.camera.width, scene.camera.height) == (40, 32)
    assert scene.camera.focal_px == 80.0
    assert scene.monitor.shape == (120, 200)
    assert scene.brdf.alpha_x == 0.025 and scene.brdf.alpha_y == 0.002 and scene.brdf.rho_s == 0.4
    assert scene.sampling.n_rays == 48
    assert math.isclose(scene.sampling.theta_max, math.radians(2.0))
    assert scene.estimator == "paper"
    # the camera looks at look_at_mm: that point projects to the principal point
    np.testing.assert_allclose(scene.camera.project(np.array([1.7, 2.3, 0.0])), [19.5, 15.5], atol=1e-9)
    # the monitor faces look_at_mm
    n = np.subtract([0.4, -1.1, 0.0], cfg.monitor.centre_mm)
    np.testing.assert_allclose(scene.monitor.normal, n / np.linalg.norm(n), atol=1e-15)


def test_config_round_trips_through_its_dump():
    cfg = make_config(anisotropy={"__replace__": {"frame": "rotational", "centre_mm": [1.0, 2.0, 0.0]}},
                      brdf={"__replace__": {"model": "ward", "alpha_tangential": 0.02, "alpha_radial": 0.003}})
    again = parse_config(cfg.model_dump(mode="json"))
    assert again == cfg


def test_config_is_frozen():
    cfg = make_config()
    with pytest.raises(pydantic.ValidationError):
        cfg.sampling.n_rays = 3


def test_surface_type_defaults_to_flat():
    cfg = make_config(surface={"__replace__": {"size_mm": [100.0, 80.0]}})
    assert cfg.surface.type == "flat"


def test_focal_length_in_mm_or_px():
    a = make_config(camera={"focal_length_px": None, "focal_length_mm": 16.0, "pixel_pitch_mm": 0.2})
    assert a.camera.focal_px == pytest.approx(80.0)
    b = make_config(camera={"focal_length_mm": 16.0, "pixel_pitch_mm": 0.2})  # consistent: fine
    assert b.camera.focal_px == 80.0


def test_alpha_aliases_map_to_the_rotational_frames_axes():
    cfg = make_config(anisotropy={"__replace__": {"frame": "rotational"}},
                      brdf={"__replace__": {"model": "ward", "alpha_tangential": 0.03, "alpha_radial": 0.002}})
    ward = Scene.from_config(cfg).brdf
    assert (ward.alpha_x, ward.alpha_y) == (0.03, 0.002)  # x = tangential, y = radial


def test_load_config_reads_toml_and_resolves_image_paths(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text(BASE_TOML + '\n[patterns.images]\nfiles = ["imgs/a.png"]\n')
    cfg = load_config(path)
    assert cfg.name == "toml-scene" and cfg.camera.focal_px == pytest.approx(80.0)
    assert cfg.patterns.images.files == (str((tmp_path / "imgs" / "a.png").resolve()),)


# --------------------------------------------------------------------------- bad configs

BAD = {
    "typo in a section": ({"surface": {"sise_mm": [1.0, 2.0]}}, ["surface.sise_mm", "unknown field"]),
    "typo in a section name": ({"sampeling": {"n_rays": 3}}, ["sampeling", "unknown field"]),
    "typo in brdf": ({"brdf": {"alpha_z": 0.1}}, ["brdf.alpha_z", "unknown field"]),
    "negative size": ({"surface": {"size_mm": [-100.0, 80.0]}}, ["surface.size_mm"]),
    "zero size": ({"surface": {"size_mm": [100.0, 0.0]}}, ["surface.size_mm"]),
    "zero normal": ({"surface": {"normal": [0.0, 0.0, 0.0]}}, ["surface.normal", "non-zero"]),
    "nan x_axis": ({"surface": {"x_axis": [float("nan"), 0.0, 0.0]}}, ["surface.x_axis"]),
    "zero monitor up": ({"monitor": {"up": [0.0, 0.0, 0.0]}}, ["monitor.up"]),
    "zero camera up": ({"camera": {"up": [0.0, 0.0, 0.0]}}, ["camera.up"]),
    "zero frame direction": ({"anisotropy": {"x_direction": [0.0, 0.0, 0.0]}}, ["anisotropy.x_direction"]),
    "zero turning axis": ({"anisotropy": {"frame": "rotational", "axis": [0.0, 0.0, 0.0]}},
                          ["anisotropy.axis"]),
    "x_axis along normal": ({"surface": {"x_axis": [0.0, 0.0, 2.0]}}, ["surface", "x_axis", "parallel"]),
    "missing camera position": ({"camera": {"position_mm": None}}, ["camera.position_mm", "missing"]),
    "missing monitor pitch": ({"monitor": {"pixel_pitch_mm": None}}, ["monitor.pixel_pitch_mm", "missing"]),
    "missing surface size": ({"surface": {"size_mm": None}}, ["surface.size_mm", "missing"]),
    "missing brdf": ({"brdf": None}, ["brdf", "missing"]),
    "missing brdf model": ({"brdf": {"model": None}}, ["brdf.model", "missing"]),
    "unknown brdf model": ({"brdf": {"model": "lambert"}}, ["brdf.model", "lambert"]),
    "one alpha only": ({"brdf": {"alpha_y": None}}, ["brdf", "alpha_y"]),
    "alpha aliases mixed": ({"brdf": {"alpha_radial": 0.01}}, ["brdf", "alpha_tangential"]),
    "alpha_tangential with a fixed frame": (
        {"brdf": {"__replace__": {"model": "ward", "alpha_tangential": 0.03, "alpha_radial": 0.002}}},
        ["brdf.alpha_tangential", "anisotropy.frame"]),
    "mirror with alphas": ({"brdf": {"model": "mirror"}}, ["brdf.alpha_x", "unknown field"]),
    "negative alpha": ({"brdf": {"alpha_x": -0.1}}, ["brdf.alpha_x"]),
    "unknown normalisation": ({"brdf": {"normalization": "ward"}}, ["brdf.normalization"]),
    "shifts < 3": ({"patterns": {"fringes": {"shifts": 2}}}, ["patterns.fringes.shifts"]),
    "duplicate widths": ({"patterns": {"fringes": {"widths_px": [50.0, 20.0, 50.0]}}},
                         ["patterns.fringes.widths_px", "distinct"]),
    "negative width": ({"patterns": {"fringes": {"widths_px": [-5.0]}}}, ["patterns.fringes.widths_px"]),
    "no rays": ({"sampling": {"n_rays": 0}}, ["sampling.n_rays"]),
    "cone of 90 deg": ({"sampling": {"theta_max_deg": 90.0}}, ["sampling.theta_max_deg"]),
    "estimator typo": ({"sampling": {"estimator": "weighted-mean"}}, ["sampling.estimator"]),
    "scheme typo": ({"sampling": {"scheme": "uniform"}}, ["sampling.scheme"]),
    "white below black": ({"monitor": {"black_level": 0.6, "white_level": 0.5}}, ["monitor", "white_level"]),
    "camera without focal length": ({"camera": {"focal_length_px": None}}, ["camera", "focal_length"]),
    "contradicting focal lengths": ({"camera": {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.1}},
                                    ["camera", "focal_length_px"]),
    "camera at its look_at": ({"camera": {"position_mm": [1.0, 2.0, 3.0], "look_at_mm": [1.0, 2.0, 3.0]}},
                              ["camera", "look_at_mm"]),
    "zero resolution": ({"camera": {"resolution": [0, 32]}}, ["camera.resolution"]),
    "zero tile rows": ({"compute": {"tile_rows": 0}}, ["compute.tile_rows"]),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_config_fails_naming_the_field(case):
    changes, expected = BAD[case]
    msg = error_of(changes)
    assert msg.startswith("invalid configuration")
    for text in expected:
        assert text in msg, f"{case}: {text!r} not in\n{msg}"
    # the path is the one written in the file: no pydantic union tags inside it
    assert ".ward." not in msg and ".flat." not in msg and ".mirror." not in msg


def test_every_error_is_reported_at_once():
    msg = error_of({"surface": {"size_mm": [-1.0, 1.0]}, "sampling": {"n_rays": 0},
                    "patterns": {"fringes": {"shifts": 1}}})
    for path in ("surface.size_mm", "sampling.n_rays", "patterns.fringes.shifts"):
        assert f"  {path}" in msg


def test_error_lines_start_with_the_dotted_path():
    msg = error_of({"surface": {"size_mm": [-100.0, 80.0]}})
    lines = msg.splitlines()[1:]
    assert lines and all(line.startswith("  surface.size_mm") for line in lines)


def test_missing_config_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="not found") as info:
        load_config(path)
    assert str(path) in str(info.value)


def test_invalid_toml(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text(BASE_TOML + "\n[sampling\nn_rays = 3\n")
    with pytest.raises(ConfigError, match="TOML") as info:
        load_config(path)
    assert str(path) in str(info.value)


def test_bad_field_in_a_file_names_the_file_and_the_field(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(BASE_TOML.replace("size_mm = [100.0, 80.0]", "size_mm = [100.0, -80.0]"))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert "surface.size_mm" in str(info.value) and str(path) in str(info.value)


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)
    with pytest.raises(ValueError):
        parse_config({})
    assert isinstance(make_config(), RunConfig)


@pytest.mark.parametrize("name", ["..", ".hidden", "a/b", "figures", "run.zarr", "x."])
def test_variant_names_must_be_safe_folder_names(name):
    from conftest import base_dict

    data = base_dict()
    data["variants"] = [{"name": name}]
    with pytest.raises(ConfigError) as err:
        parse_config(data)
    assert "variants.0.name" in str(err.value)
