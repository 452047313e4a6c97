"""Small scenes for the simulator tests (a few thousand rays: fast, but every code path).

The base scene (``base_dict``): a flat 100 mm x 80 mm plate at the origin (normal +z); a
40 x 32 px pinhole camera 300 mm away, 25 deg off the normal in the y-z plane; a
200 x 120 px monitor (1 mm pixels) 200 mm away on the mirrored side, facing the plate. The
poses are nudged off the symmetric positions so that no ray lands exactly on a monitor
pixel boundary. The camera sees the plate in its middle and empty space round it, and the
monitor's reflection covers most but not all of the plate: every test scene has pixels that
miss the plate and bundles that (partly) miss the monitor.
"""

from __future__ import annotations

import copy
import math
import sys
from pathlib import Path

import pytest

#: The tests are laid out like the package (tests/render/, tests/store/, ...). ``import naive``
#: (the slow references) and the helpers some test modules share (``from test_pipeline
#: import tiny_config_dict``) work from a test module in any folder.
TESTS = Path(__file__).parent
sys.path[:0] = [str(TESTS)] + sorted(str(d) for d in TESTS.iterdir()
                                     if d.is_dir() and any(d.glob("test_*.py")))

from pmdsim.config import parse_config  # noqa: E402

TILT = math.radians(25.0)
CAMERA_DISTANCE_MM = 300.0
MONITOR_DISTANCE_MM = 200.0


def base_dict() -> dict:
    """A fresh, valid configuration mapping of the base scene (see the module docstring)."""
    s, c = math.sin(TILT), math.cos(TILT)
    return {
        "name": "test-scene",
        "camera": {
            "resolution": [40, 32],
            "focal_length_px": 80.0,
            "position_mm": [3.1, -CAMERA_DISTANCE_MM * s, CAMERA_DISTANCE_MM * c],
            "look_at_mm": [1.7, 2.3, 0.0],
            "up": [0.0, 1.0, 0.0],
        },
        "monitor": {
            "resolution": [200, 120],
            "pixel_pitch_mm": 1.0,
            "centre_mm": [-2.3, MONITOR_DISTANCE_MM * s + 0.7, MONITOR_DISTANCE_MM * c],
            "look_at_mm": [0.4, -1.1, 0.0],
            "up": [0.0, 1.0, 0.0],
        },
        "surface": {"type": "flat", "size_mm": [100.0, 80.0]},
        "anisotropy": {"frame": "fixed", "x_direction": [1.0, 0.0, 0.0]},
        "brdf": {"model": "ward", "alpha_x": 0.025, "alpha_y": 0.002, "rho_s": 0.4},
        # mode "stratified" (the default before issue 18's rules): the naive references
        # take its sample set (P + lattice, equal weights); tests of the rules set "rule"
        "sampling": {"n_rays": 48, "theta_max_deg": 2.0, "mode": "stratified"},
        "compute": {"tile_rows": 8, "scheduler": "threads", "num_workers": 2},
    }


def merge(data: dict, changes: dict) -> dict:
    """Deep-merge ``changes`` into a copy of ``data``; a value ``None`` deletes the key; a
    section given as ``{"__replace__": {...}}`` replaces the whole section."""
    out = copy.deepcopy(data)
    for key, val in changes.items():
        if val is None:
            out.pop(key, None)
        elif isinstance(val, dict) and "__replace__" in val:
            out[key] = copy.deepcopy(val["__replace__"])
        elif isinstance(val, dict) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], val)
        else:
            out[key] = copy.deepcopy(val)
    return out


def make_config(**changes):
    """A validated :class:`~pmdsim.config.RunConfig` of the base scene with section changes,
    e.g. ``make_config(brdf={"alpha_x": 0.01}, sampling={"mode": "random"})``."""
    return parse_config(merge(base_dict(), changes))


def make_simulation(**changes):
    from pmdsim.render import Simulation

    return Simulation.from_config(make_config(**changes))


@pytest.fixture
def base_config():
    return make_config()


@pytest.fixture
def mirror_config():
    return make_config(brdf={"__replace__": {"model": "mirror"}})
