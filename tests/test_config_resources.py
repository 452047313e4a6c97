"""The memory and time estimate of a configuration (:func:`pmdsim.config.estimate_resources`)
and the check that stops a run that cannot fit before anything is allocated."""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import make_config
from pmdsim.config import ConfigError, check_resources, estimate_resources, load_config

EXAMPLES = Path(__file__).parent.parent / "examples"
GB = 2**30


def _first_field(msg: str) -> str:
    return msg.splitlines()[1].strip().split(":")[0]


def test_memory_grows_with_the_camera_pixels_and_the_fringe_images():
    small = estimate_resources(make_config())
    big = estimate_resources(make_config(camera={"resolution": [400, 320]}))
    # 100x the pixels: the per-pixel part grows 100x on top of the fixed interpreter base
    from pmdsim.config import BASE_MEMORY_BYTES
    per_px_small = small.memory_bytes - BASE_MEMORY_BYTES - small.parts.get("sampling.n_rays", 0)
    per_px_big = big.memory_bytes - BASE_MEMORY_BYTES - big.parts.get("sampling.n_rays", 0)
    assert per_px_big / per_px_small == pytest.approx(100, rel=0.15)
    more = estimate_resources(make_config(patterns={"fringes": {"widths_px": [20.0, 50.0, 400.0],
                                                                "shifts": 8}}))
    assert more.parts["patterns.fringes"] > 2 * small.parts["patterns.fringes"]
    # rays: pixels x rays per pixel x passes (+ the one-ray specular reference)
    assert big.rays == pytest.approx(400 * 320 * (48 + 1))


def test_a_huge_camera_is_refused_naming_its_resolution():
    cfg = make_config(camera={"resolution": [60000, 60000]})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=64 * GB)
    msg = str(info.value)
    assert _first_field(msg) == "camera.resolution" and "64 GB" in msg


def test_too_many_rays_are_refused_naming_n_rays():
    cfg = make_config(sampling={"n_rays": 10_000_000})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=16 * GB)
    assert _first_field(str(info.value)) == "sampling.n_rays"


def test_too_many_dots_are_refused_naming_the_dots():
    cfg = make_config(camera={"resolution": [1280, 1024]},
                      patterns={"fringes": False, "dots": {"grid": [100, 100]}})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=16 * GB)
    assert _first_field(str(info.value)) == "patterns.dots"


def test_cpu_time_over_the_limit_is_refused_and_the_limit_can_be_raised():
    cfg = make_config(camera={"resolution": [2000, 2000]}, sampling={"n_rays": 1_000_000})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=10**15)
    assert _first_field(str(info.value)) == "sampling.n_rays"
    assert "compute.max_cpu_hours" in str(info.value)
    raised = make_config(camera={"resolution": [2000, 2000]}, sampling={"n_rays": 1_000_000},
                         compute={"max_cpu_hours": 1e6})
    check_resources(raised, available_bytes=10**15)


@pytest.mark.parametrize("name", ["paper_fig3.toml", "roughness_comparison.toml", "dot_scan.toml"])
def test_the_examples_fit_a_laptop(name):
    est = check_resources(load_config(EXAMPLES / name), available_bytes=8 * GB)
    assert est.memory_bytes < 4 * GB
