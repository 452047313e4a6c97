"""camera.roi: a window of the sensor renders exactly those pixels of the whole sensor;
"auto" holds every pixel that sees the part; the estimate counts the rendered pixels."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import ConfigError, estimate_resources, parse_config
from pmdsim.render import Simulation
from pmdsim.run.simulate import resolve_roi

from conftest import base_dict, merge

SMALL_PART = {"__replace__": {"type": "sphere", "radius_mm": -900.0,
                              "aperture": {"shape": "circular", "radius_mm": 18.0, "centre_mm": [3.0, -2.0]}}}


def _cfg(**changes):
    d = merge(base_dict(), {"camera": {"resolution": [64, 48], "focal_length_px": None,
                                       "camera_matrix": [[130.0, 0, 30.7], [0, 127.0, 22.2], [0, 0, 1]],
                                       "k1": -0.05, "p2": 0.002},
                            "brdf": {"__replace__": {"model": "mirror"}}})
    return parse_config(merge(d, changes))


def test_window_renders_the_same_pixels():
    full = Simulation.from_config(_cfg()).geometry()
    roi = (9, 5, 37, 29)  # col0, row0, width, height: odd sizes, off centre
    win = Simulation.from_config(_cfg(camera={"roi": list(roi)})).geometry()
    c0, r0, w, h = roi
    assert win.specular_u.shape == (h, w)
    for a, b in ((win.specular_u, full.specular_u), (win.specular_v, full.specular_v),
                 (win.surface_mask, full.surface_mask)):
        np.testing.assert_allclose(a, b[r0:r0 + h, c0:c0 + w], rtol=0, atol=1e-9, equal_nan=True)


def test_auto_window_holds_every_pixel_on_the_part():
    cfg = _cfg(surface=SMALL_PART)
    full = Simulation.from_config(cfg).geometry()
    auto = resolve_roi(cfg.model_copy(update={"camera": cfg.camera.model_copy(update={"roi": "auto"})}))
    c0, r0, w, h = auto.camera.roi
    rows, cols = np.nonzero(full.surface_mask)
    assert rows.min() >= r0 and rows.max() < r0 + h and cols.min() >= c0 and cols.max() < c0 + w
    assert w * h < 0.6 * 64 * 48  # the part fills a part of the frame
    win = Simulation.from_config(auto).geometry()
    assert win.surface_mask.sum() == full.surface_mask.sum()
    # the estimate counts the rendered pixels
    e_full = estimate_resources(cfg).parts["camera.resolution"]
    e_win = estimate_resources(auto).parts["camera.resolution"]
    assert e_win / e_full == pytest.approx(w * h / (64 * 48))
    # Scene.from_config resolves "auto" by itself (Python API)
    direct = Simulation.from_config(cfg.model_copy(update={"camera": cfg.camera.model_copy(update={"roi": "auto"})}))
    assert direct.shape == (h, w)


def test_window_outside_the_sensor_is_refused():
    with pytest.raises(ConfigError, match="camera: roi"):
        _cfg(camera={"roi": [40, 0, 30, 10]})
