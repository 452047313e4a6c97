"""Fringes on a nearest-pixel monitor by the control variate (issue 18,
:mod:`pmdsim.render.control`): the Gauss rule for the smooth fringe plus rqmc replicates
of the staircase residual.

References of other methods: the Cranley-Patterson-rotated lattice with 64 x the rays
(mode ``random``, the kernel's table sums), and a NumPy sum over the rays of
:meth:`~pmdsim.render.Simulation.transport` (the nearest monitor column looked up by hand),
independent of the kernel's pattern phase and of the control variate.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_config
from pmdsim.patterns import phase_shifts
from pmdsim.render import Simulation

NEAREST = {"pixel_model": "nearest"}
GAMMA = {"pixel_model": "nearest", "gamma": 2.2, "bit_depth": 8, "black_level": 0.01}


def _phase(fr):
    """(nd, nw, H, W) decoded phase of the images: arg sum_k I_k exp(-i delta_k)."""
    rot = np.exp(-1j * np.asarray(fr.shifts))
    return np.angle(np.tensordot(rot, np.moveaxis(fr.images.astype(np.float64), 2, 0), axes=1))


@pytest.fixture(scope="module")
def lattice_reference():
    """The randomised lattice at 16384 rays per pixel: linear and gamma 2.2 monitors."""
    out = {}
    for name, mon in (("linear", NEAREST), ("gamma", GAMMA)):
        cfg = make_config(sampling={"n_rays": 16384, "mode": "random", "seed": 5}, monitor=mon)
        out[name] = Simulation.from_config(cfg).render_fringes([20.0], ["x", "y"])
    return out


@pytest.mark.parametrize("display", ["linear", "gamma"])
def test_control_variate_error_bounds_the_true_one(display, lattice_reference):
    """Mode 'rule' on a nearest monitor renders the control variate: its stated phase error
    bounds the error against the lattice reference in >= 95 % of the pixels, is no blanket
    (median stated / true < 20) and is several times smaller than plain rqmc's at the same
    rays (what the control variate is for). Measured (paper estimator, 20 px fringes on 1 mm
    pixels, N = 256): coverage 0.967 (linear) and 0.969 (gamma 2.2), median stated / true
    3.6; true error 9.5 mrad RMS against plain rqmc's 26.8, stated median 21 against 61."""
    mon = NEAREST if display == "linear" else GAMMA
    fr = Simulation.from_config(make_config(sampling={"n_rays": 256, "mode": "rule"},
                                            monitor=mon)).render_fringes([20.0], ["x", "y"])
    assert fr.sampling["mode"] == "rule+rqmc" and fr.sampling["error"] == "replicates"
    plain = Simulation.from_config(make_config(sampling={"n_rays": 256, "mode": "rqmc"},
                                               monitor=mon)).render_fringes([20.0], ["x", "y"])
    ref = lattice_reference[display]
    with np.errstate(invalid="ignore", divide="ignore"):
        mod = np.abs(np.tensordot(np.exp(-1j * phase_shifts(4)),
                                  np.moveaxis(ref.images.astype(np.float64), 2, 0), axes=1))
        ok = np.isfinite(mod) & (mod > 0.1 * np.nanmax(mod))
        true = np.abs(np.angle(np.exp(1j * (_phase(fr) - _phase(ref)))))[ok]
    stated = fr.phase_error()[ok]
    assert true.size > 500
    assert np.mean(stated >= true) >= 0.95
    assert np.median(stated) < 20 * np.median(true)
    if display == "linear":  # the same statement from the sums' errors
        assert fr.sums_err is not None
    plain_stated = plain.phase_error()
    if plain_stated is not None:
        assert np.median(stated) < 0.5 * np.median(plain_stated[ok])


def test_control_variate_matches_a_numpy_sum_over_the_rays():
    """At a few pixels, the fringe sums equal a NumPy sum ``sum_j w_j cos/sin(2 pi c_j / P)``
    over the nearest monitor columns ``c_j`` of the rays of :meth:`transport` (the random
    lattice with 2^16 rays: its Monte-Carlo error, a few 1e-3 of |S|, is the tolerance:
    5 times the standard error over 16 independent blocks)."""
    cfg = make_config(sampling={"n_rays": 256, "mode": "rule"}, monitor=NEAREST)
    fr = Simulation.from_config(cfg).render_fringes([20.0], ["x"])
    big = Simulation.from_config(make_config(sampling={"n_rays": 2**16, "mode": "random",
                                                       "seed": 11}, monitor=NEAREST))
    rows, cols = np.array([12, 16, 20]), np.array([14, 20, 27])
    u, _, w, _, _ = big.transport(rows, cols, directions=False)
    c = np.floor(np.where(np.isfinite(u), u, 0.0) + 0.5)
    z = np.where(w > 0, w * np.exp(2j * np.pi * c / 20.0), 0.0) / w.shape[1]
    blocks = z.reshape(z.shape[0], 16, -1).sum(axis=2) * 16
    want = blocks.mean(axis=1)
    se = blocks.std(axis=1, ddof=1) / 4
    got = fr.sums[0, 0, rows, cols]
    assert np.all(np.abs(want) > 0.05)
    assert np.all(np.abs(got - want) < 5 * np.abs(se) + 1e-12), (got, want, se)
    # and the stated error is of the size of the actual one, not zero
    assert np.all(fr.phase_error()[0, 0, rows, cols] > 1e-7)


def test_only_nearest_rule_renders_use_the_control_variate():
    """The continuous monitor keeps the rule; mode 'rqmc' stays plain rqmc; the mirror a
    principal ray."""
    cont = Simulation.from_config(make_config(sampling={"n_rays": 64, "mode": "rule"},
                                              monitor={"pixel_model": "continuous"}))
    assert cont.render_fringes([20.0], ["x"]).sampling["mode"] == "rule"
    rq = Simulation.from_config(make_config(sampling={"n_rays": 64, "mode": "rqmc"}, monitor=NEAREST))
    assert rq.render_fringes([20.0], ["x"]).sampling["mode"] == "rqmc"


def test_diagnostics_state_the_control_variates_error():
    """The run's diagnostics (``diag_phase_se``) state, from the rays of ``transport``, the
    same phase error the control-variate render states at those pixels (same sample sets;
    a NumPy sum, independent of the kernel's pattern phase)."""
    from pmdsim.studies import diagnostics as dg

    cfg = make_config(sampling={"n_rays": 64, "mode": "rule"}, monitor=NEAREST)
    sim = Simulation.from_config(cfg)
    fr = sim.render_fringes([20.0], ["x", "y"])
    grid = dg.PixelGrid(np.arange(6, 27, 5), np.arange(8, 33, 6), sim.shape)
    se = dg.phase_error_rule(sim, grid, (20.0,), ("x", "y"))
    want = fr.phase_error()[:, :, grid.rows[:, None], grid.cols[None, :]]
    ok = np.isfinite(se) & np.isfinite(want)
    assert ok.sum() >= 30
    np.testing.assert_allclose(se[ok], want[ok], rtol=1e-6)


def test_rays_traced_count_the_control_variates_passes():
    """A control-variate render traces the rule (3 x 16 of n_rays = 48) and its embedded
    rule (2 x 12), then the 8 replicates of 6 points twice (profiles and smooth part)."""
    from pmdsim.render import control

    sim = Simulation.from_config(make_config(sampling={"n_rays": 48, "mode": "rule"},
                                             monitor=NEAREST))
    assert control.applies(sim)
    assert control.rays_share(sim) == pytest.approx((48 + 24) / 48 + 2.0)
