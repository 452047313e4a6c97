"""Tests of the machining -> parameters functions and the diffractive model
(``pmdsim.brdf.turning``).

- f = 30 um, r = 0.5 mm: alpha_radial = f / (sqrt(6) r) = 0.0245 (kinematic part), exact
  RMS arc slope, regime;
- Kirchhoff efficiencies against ``scipy.integrate.quad`` of the same integral to 1e-6;
- the simulated orders (diffractive model, transport of one pixel) sit at the grating
  equation's positions on the monitor to 0.1 monitor px (oblique incidence, radial plane);
- shrinking the wavelength turns the diffractive model's fringe modulation into the
  geometric (kinematic) one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from test_radiometric import _decoded_modulation, _facing_config
from pmdsim.brdf import turning
from pmdsim.config import parse_config
from pmdsim.render import Simulation


def test_texture_parameters_of_the_issue_example():
    p = turning.texture_parameters(30.0, 0.5, rq_um=0.005, correlation_length_um=5.0,
                                   wavelength_nm=545.0, distance_mm=600.0, pixel_pitch_mm=0.25)
    assert round(p.kinematic_alpha_radial_small_slope, 4) == 0.0245
    assert abs(p.kinematic_alpha_radial_small_slope - 0.03 / (math.sqrt(6) * 0.5)) < 1e-15
    # exact arcs: mean of x^2 / (r^2 - x^2) over the period, by quadrature
    ms, _ = integrate.quad(lambda x: x * x / (0.25 - x * x), -0.015, 0.015, epsabs=1e-16)
    assert abs(p.kinematic_alpha_radial - math.sqrt(2 * ms / 0.03)) < 1e-12
    assert abs(p.rt_um - 0.03**2 / (8 * 0.5) * 1e3) < 1e-3
    assert abs(p.random_alpha - 2 * 0.005 / 5.0) < 1e-15
    assert abs(p.specular_share_random - math.exp(-((4 * math.pi * 5e-6 / 545e-6) ** 2))) < 1e-15
    spacing = 545e-6 / 0.03
    assert abs(p.order_spacing_monitor_px - spacing * 600 / 0.25) < 1e-9
    assert abs(p.orders_in_lobe - (2 * 0.03 / 0.5) / spacing) < 1e-9
    assert p.regime == "diffractive"  # 6.6 orders in the lobe, ~44 px apart
    assert turning.texture_parameters(300.0, 0.5, wavelength_nm=545.0).regime == "geometric"
    assert turning.texture_parameters(3.0, 5.0, wavelength_nm=545.0).regime == "specular"
    assert "regime" in turning.format_texture(p)


@pytest.mark.parametrize("lam_nm, theta_deg", [(545.0, 0.0), (465.0, 30.0), (1200.0, 10.0)])
def test_efficiencies_match_quadrature(lam_nm, theta_deg):
    f, r = 0.03, 0.5
    lam, th = lam_nm * 1e-6, math.radians(theta_deg)
    m = turning.propagating_orders(lam, f, th)
    assert np.all(np.abs(math.sin(th) + m * lam / f) < 1)
    eta = turning.order_efficiencies(f, r, lam, th, m)
    for mm, e in zip(m[:: max(1, m.size // 12)], eta[:: max(1, m.size // 12)]):
        s = math.sin(th) + mm * lam / f
        kk = 2 * math.pi / lam * (math.cos(th) + math.sqrt(1 - s * s))

        def ph(x):
            return kk * (r - math.sqrt(r * r - x * x)) - 2 * math.pi * mm * x / f

        re, _ = integrate.quad(lambda x: math.cos(ph(x)), -f / 2, f / 2, limit=400, epsabs=1e-14)
        im, _ = integrate.quad(lambda x: math.sin(ph(x)), -f / 2, f / 2, limit=400, epsabs=1e-14)
        ref = (re * re + im * im) / (f * f)
        assert abs(e - ref) < 1e-6, f"m = {mm}: {e} vs quad {ref}"
    assert 0.95 < eta.sum() < 1.05  # a thin phase screen conserves energy to O(slope^2)


def _order_config(theta_deg, lam_nm, d=500.0):
    brdf = {"model": "turned", "regime": "diffractive", "feed_um": 30.0, "nose_radius_mm": 0.5,
            "rms_slope_tangential": 5e-5, "rms_slope_radial": 5e-5,
            "wavelengths_nm": [lam_nm], "spectral_weights": [1.0], "incidence_deg": theta_deg}
    data = _facing_config(theta_deg, brdf, d, n_rays=20000, monitor_px=3000).model_dump()
    # radial (local y = n x x) along world -x: in the plane of incidence
    data["anisotropy"] = {"frame": "fixed", "x_direction": [0.0, 1.0, 0.0]}
    return parse_config(data)


def test_orders_sit_at_the_grating_equation():
    theta, lam, f, d = 20.0, 545e-6, 0.03, 500.0
    sim = Simulation.from_config(_order_config(theta, lam * 1e6, d))
    u, v, w, dirs, origin = sim.transport([0], [0])
    hit = np.isfinite(u[0]) & (w[0] > 0)
    u, w = u[0][hit], w[0][hit]
    # expected: directions at sin(theta_m) = sin(theta_i) + m lambda / f in the plane of
    # incidence (x-z), intersected with the monitor
    th = math.radians(theta)
    m = turning.propagating_orders(lam, f, th)
    s = math.sin(th) + m * lam / f
    world = np.stack([s, np.zeros_like(s), np.sqrt(1 - s * s)], -1)
    mu, mv, ok = sim.scene.monitor.intersect(origin[0], world)
    expected = np.sort(mu[ok])
    spacing = np.min(np.diff(expected))
    assert spacing > 50  # orders ~ 90 px apart
    nearest = np.argmin(np.abs(u[:, None] - expected[None]), axis=1)
    found = 0
    for k in np.unique(nearest):
        sel = nearest == k
        if w[sel].sum() < 0.01 * w.sum():
            continue
        centre = np.sum(u[sel] * w[sel]) / w[sel].sum()
        assert abs(centre - expected[k]) < 0.1, f"order at {centre:.3f} px, expected {expected[k]:.3f}"
        assert np.ptp(u[sel]) < 0.2 * spacing  # a sharp spot
        found += 1
    assert found >= 5


def test_diffractive_tends_to_geometric_as_wavelength_shrinks():
    """Radial-fringe modulation (3 periods) of the diffractive model approaches the
    geometric (kinematic) model's as lambda / f -> 0 (the order comb becomes finer than
    the random-roughness lobe); the difference shrinks monotonically."""
    d = 500.0
    rough = {"feed_um": 30.0, "nose_radius_mm": 0.5, "rms_slope_tangential": 1e-3,
             "rms_slope_radial": 1e-3}
    periods_px = [1880.0, 1110.0, 750.0]  # x = k d f / r = 1.0, 1.7, 2.5 (0.1 mm px)

    def modulation(brdf):
        sim = Simulation.from_config(_facing_config(0.0, brdf, d, n_rays=8192, monitor_px=3000))
        return np.array([_decoded_modulation(sim.render_fringes((p,), ("y",), 4)) for p in periods_px])

    geo = modulation({"model": "turned", "regime": "geometric", **rough})
    errors = []
    for lam in (2000.0, 500.0, 100.0, 50.0):
        dif = modulation({"model": "turned", "regime": "diffractive", "wavelengths_nm": [lam],
                          "spectral_weights": [1.0], **rough})
        errors.append(np.max(np.abs(dif - geo)))
    # measured 0.47, 0.12, 0.023, 0.011: the Kirchhoff edge ripple fades ~ sqrt(lambda)
    assert errors[0] > 0.2, errors  # at 2 um the comb is coarse: clearly not geometric
    assert errors[0] > errors[1] > errors[2] > errors[3], errors
    assert errors[3] < 0.015, errors
