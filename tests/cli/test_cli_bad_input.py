"""Bad command-line input of every command is exit code 2 with a message naming the option
or field, checked before any computation (issue 21's list)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import base_dict, merge
from pmdsim.cli import app
from pmdsim.config import ConfigError, InputError, parse_config


def _toml(data: dict, prefix: str = "") -> str:
    plain = [f"{k} = {json.dumps(v)}" for k, v in data.items() if not isinstance(v, dict)]
    out = ([f"[{prefix}]"] if prefix and plain else []) + plain
    for k, v in data.items():
        if isinstance(v, dict):
            out.append(_toml(v, f"{prefix}.{k}" if prefix else k))
    return "\n".join(out) + "\n"


@pytest.fixture
def config_file(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text(_toml(base_dict()))
    return path


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.mark.parametrize("option, value, says", [
    ("--theta", "nan", "--theta"), ("--theta", "1,-2", "--theta"),
    ("--n-values", "0", "--n-values"), ("--camera", "0x0", "--camera"),
    ("--camera", "12", "--camera"),
])
def test_converge_options(tmp_path, config_file, option, value, says):
    out = tmp_path / "conv"
    result = _invoke("converge", config_file, "-o", out, option, value)
    assert result.exit_code == 2, result.output
    assert says in result.output and not out.exists()


@pytest.mark.parametrize("option, value", [("--max-order-residual", "0.9"),
                                           ("--max-order-residual", "0"),
                                           ("--min-relative-amplitude", "nan")])
def test_decode_options_are_checked_before_the_images(tmp_path, option, value):
    result = _invoke("decode", tmp_path / "missing.tif", "-o", tmp_path / "d", "--widths",
                     "50,400", "--shifts", "4", "--extent-px", "1000", option, value)
    assert result.exit_code == 2, result.output
    assert option in result.output


def test_decode_of_mixed_bit_depths_is_refused(tmp_path):
    import tifffile

    from pmdsim.measure.images import load_image_stack

    paths = []
    for k in range(8):
        img = (np.arange(12 * 10).reshape(12, 10) * (k + 1)) % 200
        p = tmp_path / f"f{k}.tif"
        tifffile.imwrite(p, img.astype(np.uint16 if k == 5 else np.uint8))
        paths.append(p)
    with pytest.raises(InputError, match=r"f5\.tif.*uint16.*uint8"):
        load_image_stack(paths)
    result = _invoke("decode", *paths, "-o", tmp_path / "d", "--widths", "50,400", "--shifts",
                     "4", "--extent-px", "300")
    assert result.exit_code == 2 and "uint16" in result.output
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("command", ["texture", "fit", "report"])
def test_output_naming_a_file_is_refused_first(tmp_path, config_file, command):
    f = tmp_path / "taken"
    f.write_text("keep")
    args = {"texture": ["texture", "--feed-um", "10", "--nose-radius-mm", "1"],
            "fit": ["fit", config_file, tmp_path / "img.tif"],
            "report": ["report", tmp_path]}[command]
    result = _invoke(*args, "-o", f)
    assert result.exit_code == 2, result.output
    assert "is a file" in result.output and f.read_text() == "keep"


def test_budget_of_a_huge_camera_is_refused_naming_the_resolution(tmp_path):
    cfg = tmp_path / "big.toml"
    cfg.write_text(_toml(merge(base_dict(), {"camera": {"resolution": [20000, 16000],
                                                        "focal_length_px": 40000.0}})))
    result = _invoke("budget", cfg, "-o", tmp_path / "b")
    assert result.exit_code == 2, result.output
    assert "camera.resolution" in result.output and not (tmp_path / "b").exists()


def test_files_with_a_number_names_the_item_only():
    with pytest.raises(ConfigError) as info:
        parse_config(merge(base_dict(), {"patterns": {"images": {"files": [1]}}}))
    assert "patterns.images.files.0" in str(info.value)
    assert "at least 1 item" not in str(info.value)


def test_a_thin_lens_whose_centre_misses_the_part_is_a_clean_error():
    from pmdsim.scene import Scene

    cfg = parse_config(merge(base_dict(), {"camera": {
        "focal_length_mm": 16.0, "pixel_pitch_mm": 0.2, "focal_length_px": None,
        "f_number": 4.0, "look_at_mm": [400.0, 2.3, 0.0]}}))
    with pytest.raises(ConfigError, match="camera.focus_distance_mm"):
        Scene.from_config(cfg)


def test_converge_is_sized_before_it_renders(tmp_path, config_file):
    """Its largest render (10 million rays per pixel) cannot fit: refused naming the study
    and the setting, before any output."""
    from pmdsim.config.resources import convergence_configs

    cfg = parse_config(base_dict())
    runs = convergence_configs(cfg, [10, 20], [1.0], ["paper", "radiometric"], (16, 12))
    # paper: N in {10, 20, 48} x theta in {1, 2}; radiometric: N in {10, 20, 48}
    assert len(runs) == 3 * 2 + 3
    assert {r.camera.resolution for r in runs} == {(16, 12)}
    out = tmp_path / "conv"
    result = _invoke("converge", config_file, "-o", out, "--n-values", "10000000",
                     "--camera", "4000x3000")
    assert result.exit_code == 2, result.output
    assert "converge:" in result.output and "sampling.n_rays" in result.output
    assert not out.exists()


def test_budget_refuses_a_sensor_without_signal_naming_it(tmp_path):
    cfg = tmp_path / "dark.toml"
    cfg.write_text(_toml(merge(base_dict(), {"sensor": {"enabled": True,
                                                        "dark_signal_electrons": 20000.0}})))
    result = _invoke("budget", cfg, "-o", tmp_path / "b")
    assert result.exit_code == 2, result.output
    assert "sensor.dark_signal_electrons" in result.output and not (tmp_path / "b").exists()
