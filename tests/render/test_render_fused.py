"""The rule and its embedded rules rendered in one tile task (:func:`pmdsim.render.geometry_rows.
render_rule_fused`) against the passes rendered one after another, with the error computed
over the whole differences afterwards (:func:`pmdsim.render.fringe_finish.fringe_errors`), and the
nearest monitor's rqmc replicates in one tile task (:func:`pmdsim.render.geometry_rows.
replicates_fused`) against the whole-camera loop: the same bytes, on tiles that do not
divide the camera."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import parse_config
from pmdsim.render import Simulation
from pmdsim.render import simulation as simulation_mod
from test_quadrature import fig3


def _render(cfg, fused: bool, monkeypatch, widths=(50.0, 400.0, 3200.0), module=None,
            names=("render_rule_fused", "fuses")):
    """The fringes of ``cfg`` on tiles of 5 rows (32 rows: six tiles of 5 and one of 2),
    2 threads, with the fused path ``names[0]`` of ``module`` on or (``fused=False``) its
    test ``names[1]`` refusing; and how often the fused path ran."""
    module = simulation_mod if module is None else module
    calls = []
    original = getattr(module, names[0])

    def counted(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    with monkeypatch.context() as mp:
        mp.setattr(module, names[0], counted)
        if not fused:
            mp.setattr(module, names[1], lambda *args: False)
        sim = Simulation.from_config(cfg)
        sim.tile_rows, sim.num_workers = 5, 2
        # the embedded rules' statement (the pilot's took its place in render_fringes on a
        # continuous monitor, issue 36; _fringes_once still renders it)
        fr = (sim._fringes_once(widths, ["x", "y"], 4, None) if sim.pilot_applies()
              else sim.render_fringes(widths, ["x", "y"], 4))
    return fr, len(calls)


@pytest.mark.parametrize("estimator", ["paper", "weighted_mean", "radiometric"])
def test_the_embedded_rules_in_the_rules_tiles_give_the_same_bytes(estimator, monkeypatch):
    d = fig3(n_rays=256, mode="rule")
    d["sampling"]["estimator"] = estimator
    d["brdf"]["alpha_y"] = 0.003  # unequal alphas, a lobe narrower along y
    d["camera"]["position_mm"] = [-845.2, 420.0, 1812.6]  # off the x-z plane: phi0 varies
    cfg = parse_config(d)
    fused, n_fused = _render(cfg, True, monkeypatch)
    apart, n_apart = _render(cfg, False, monkeypatch)
    assert (n_fused, n_apart) == (1, 0)
    assert fused.sampling["passes"] == 3 and fused.sampling == apart.sampling
    assert np.isfinite(fused.sums).any()
    for name in ("images", "sums", "f_total", "f_hit", "sums_err"):
        a, b = getattr(fused, name), getattr(apart, name)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), name
    assert np.array_equal(fused.convergence, apart.convergence)
    assert np.array_equal(fused.phase_error(), apart.phase_error(), equal_nan=True)


@pytest.mark.parametrize("estimator, gamma, widths, alpha_y, mode", [
    ("paper", 1.0, (50.0, 400.0, 3200.0), 0.003, "rule+rqmc"),  # the cone: no box rule
    ("paper", 2.2, (50.0, 400.0, 3200.0), 0.003, "rule+rqmc"),  # a response: its harmonics
    # a wide radiometric lobe, periods not integer: the box rule and the profile's rest
    ("radiometric", 2.2, (50.5, 401.0, 3200.0), 0.02, "rule+box+rqmc"),
])
def test_the_replicates_in_the_tiles_give_the_same_bytes(estimator, gamma, widths, alpha_y,
                                                         mode, monkeypatch):
    """The nearest monitor's control variate with every rqmc replicate rendered in each
    tile's task (:func:`pmdsim.render.tile_tasks.replicates_fused`) against the replicates
    rendered one after another over the whole camera: the same bytes."""
    d = fig3(n_rays=64, mode="rule")
    d["monitor"].update(pixel_model="nearest", gamma=gamma)
    d["brdf"]["alpha_y"] = alpha_y
    d["sampling"]["estimator"] = estimator
    if estimator == "paper":  # off the x-z plane: phi0 varies (the box case keeps Fig. 3's)
        d["camera"]["position_mm"] = [-845.2, 420.0, 1812.6]
    cfg = parse_config(d)
    from pmdsim.render import control_variate as control

    cv = dict(module=control, names=("replicates_fused", "fuses_replicates"))
    fused, n_fused = _render(cfg, True, monkeypatch, widths, **cv)
    apart, n_apart = _render(cfg, False, monkeypatch, widths, **cv)
    assert fused.sampling["mode"] == mode and fused.sampling == apart.sampling
    assert (n_fused, n_apart) == (1, 0)
    for name in ("images", "sums", "f_total", "f_hit", "sums_err"):
        a, b = getattr(fused, name), getattr(apart, name)
        if a is None:
            assert b is None, name
            continue
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), name
    assert np.array_equal(fused.phase_error(), apart.phase_error(), equal_nan=True)
