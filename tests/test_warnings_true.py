"""The diagnostics' warnings are true: each fires only when its condition holds (NaN and
tiny samples handled explicitly), and applying a warning's suggested setting makes that
warning go away (the suggestion is re-checked by running the diagnostics again)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import base_dict, merge
from pmdsim.config import parse_config
from pmdsim.render import Simulation
from pmdsim.run.diagnostics import diagnose_run
from pmdsim.studies import diagnostics as dg
from pmdsim.studies.coverage import off_monitor_mask

GRID = {"grid": [6, 5]}


def _config(changes: dict):
    return parse_config(merge(base_dict(), merge({"diagnostics": GRID}, changes)))


def _warnings(cfg, exclude=None):
    sim = Simulation.from_config(cfg)
    return {w.code: w for w in diagnose_run(cfg, sim, sim.geometry(), exclude=exclude).warnings}


def _apply(changes: dict, warning) -> dict:
    """The configuration changes plus the warning's ``setting = suggested``."""
    section, _, key = warning.setting.rpartition(".")
    patch: dict = {}
    node = patch
    for part in section.split("."):
        node = node.setdefault(part, {})
    node[key] = list(warning.suggested) if isinstance(warning.suggested, tuple) else warning.suggested
    return merge(changes, patch)


SCENARIOS = {
    # a 1 deg cone holds ~40 % of this lobe's energy
    "energy_fraction": {"sampling": {"theta_max_deg": 1.0}},
    # the default 1 mrad bound at 48 rays; a looser bound keeps the suggestion small
    "phase_error": {"sampling": {"theta_max_deg": 4.0},
                    "diagnostics": {"max_phase_error_mrad": 30.0}},
    # a wide cone about a narrow lobe: most rays carry no weight
    "effective_sample_size": {"sampling": {"theta_max_deg": 6.0, "n_rays": 200},
                              "brdf": {"alpha_x": 0.003, "alpha_y": 0.003}},
    # 4 px fringes under a 0.05 lobe (~10 monitor px wide), enough rays to tell
    "washed_out": {"brdf": {"alpha_x": 0.05, "alpha_y": 0.05},
                   "sampling": {"n_rays": 2048, "estimator": "radiometric"},
                   "patterns": {"fringes": {"widths_px": [4.0, 2000.0], "directions": ["x"]}}},
    # the same with 64 rays: the modulation cannot be told from sampling noise
    "modulation_undetermined": {"brdf": {"alpha_x": 0.05, "alpha_y": 0.05},
                                "sampling": {"n_rays": 64, "estimator": "radiometric"},
                                "patterns": {"fringes": {"widths_px": [4.0, 2000.0],
                                                         "directions": ["x"]}}},
    # one ray per pixel of a near-mirror, importance sampled: nothing to judge yet
    "too_few_rays": {"brdf": {"alpha_x": 0.0001, "alpha_y": 0.0001},
                     "sampling": {"n_rays": 1, "estimator": "radiometric"}},
}
#: the near-mirror in a 2 deg cone: every weight on the principal ray, whatever N
NEAR_MIRROR_CONE = {"brdf": {"alpha_x": 0.0001, "alpha_y": 0.0001}, "sampling": {"n_rays": 1}}
SCENARIOS["effective_sample_size (near-mirror)"] = NEAR_MIRROR_CONE


@pytest.mark.parametrize("code", list(SCENARIOS))
def test_applying_the_suggested_setting_clears_the_warning(code):
    changes = SCENARIOS[code]
    code = code.split(" ")[0]
    before = _warnings(_config(changes))
    assert code in before, f"{code} did not fire: {list(before)}"
    w = before[code]
    assert w.suggested is not None and w.setting
    after = _warnings(_config(_apply(changes, w)))
    assert code not in after, f"{w.setting} = {w.suggested} left: {after[code].message}"


def test_a_single_ray_near_mirror_is_not_called_washed_out():
    for changes in (SCENARIOS["too_few_rays"], NEAR_MIRROR_CONE):
        warns = _warnings(_config(changes))
        assert "washed_out" not in warns and "modulation_undetermined" not in warns
        assert "phase_error" not in warns
        assert set(warns) <= {"too_few_rays", "effective_sample_size", "energy_fraction"}


def test_nan_modulation_fires_no_fringe_warning():
    cfg = _config({})
    sim = Simulation.from_config(cfg)
    everything = np.ones(sim.shape, bool)  # every grid pixel excluded: all values NaN
    codes = {w.code for w in diagnose_run(cfg, sim, sim.geometry(), exclude=everything).warnings}
    assert not codes & {"washed_out", "modulation_undetermined", "phase_error", "too_few_rays",
                        "effective_sample_size"}


def test_a_half_masked_run_is_judged_on_the_pixels_it_measures():
    """The monitor moved so that many bundles hang off its edge: the phase error of those
    pixels (a truncated lobe) must not drive the n_rays suggestion; it follows the P95 of
    the pixels whose whole bundle lands on the monitor (computed independently from the
    rays of each grid pixel)."""
    changes = {"monitor": {"centre_mm": [60.0, 85.2, 181.3]},
               "diagnostics": {"max_phase_error_mrad": 1.0}}
    cfg = _config(changes)
    sim = Simulation.from_config(cfg)
    geometry = sim.geometry()
    fr = sim.render_fringes((50.0,), ("x", "y"), 4)
    off = off_monitor_mask(fr.f_total, fr.f_hit, geometry.surface_mask,
                           cfg.diagnostics.max_off_monitor_fraction)
    assert 0.1 < off[geometry.surface_mask].mean() < 0.9  # really half masked
    unmasked = {w.code: w for w in diagnose_run(cfg, sim, geometry).warnings}
    masked = {w.code: w for w in diagnose_run(cfg, sim, geometry, exclude=off).warnings}
    # independent: grid pixels whose every ray hits the monitor
    diag = dg.diagnose(sim, (50.0,), ("x", "y"), grid=tuple(cfg.diagnostics.grid))
    u, v, _, _, _ = sim.transport(diag.grid.pixel_rows, diag.grid.pixel_cols)
    on = (np.isfinite(u).all(1) & np.isfinite(v).all(1)).reshape(diag.grid.grid_shape)
    p95_on = max(np.nanpercentile(np.where(on, diag.phase_se[d, 0], np.nan), 95) for d in (0, 1))
    expected = 48 * (p95_on * 1e3 / 1.0) ** 2
    assert masked["phase_error"].suggested < 0.25 * unmasked["phase_error"].suggested
    assert 0.5 * expected < masked["phase_error"].suggested < 2.0 * expected
