"""The Rayleigh-Rice halo inside its validity (issue 38, items 5 and 6): a Rayleigh parameter
above the smooth-surface limit is refused naming ``brdf.sigma_nm`` (and the sigma that
holds), a substrate that reflects nothing names ``brdf.refractive_index``; every finish
that is accepted reflects no more than falls on it (peak plus the halo integrated over the
hemisphere, on a grid of parameters)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from conftest import base_dict, merge
from test_budget import _write_toml
from typer.testing import CliRunner

from pmdsim.brdf import rayleigh_rice as rr
from pmdsim.brdf.psd import KCorrelation
from pmdsim.cli import app
from pmdsim.config import ConfigError

ALUMINIUM = (0.96, 6.69)


def _hemispherical(model, theta0: float, reach: float, n: int = 1001) -> float:
    """The halo's directional-hemispherical reflectance at incidence ``theta0``: its BRDF
    times cos(theta_o) over the hemisphere, on the projected disk (d omega cos = dx dy), in
    the window +-``reach`` round the specular direction (the tabulated halo is 0 beyond
    its table; ``reach`` >= 1 is the whole disk)."""
    i = np.array([math.sin(theta0), 0.0, math.cos(theta0)])
    w = min(reach, 2.0)
    u = np.linspace(-w, w, n)
    ox, oy = np.meshgrid(u - i[0], u)
    inside = ox**2 + oy**2 < 1
    o = np.stack([ox[inside], oy[inside], np.sqrt(1 - ox[inside] ** 2 - oy[inside] ** 2)], -1)
    f = model.evaluate(np.broadcast_to(i, o.shape), o)
    return float(f.sum() * (u[1] - u[0]) ** 2)


GRID = list(itertools.product(
    (2.0, 20.0, 40.0),          # sigma_nm
    ((12.0, 5.0), (1.5, 0.8)),  # correlation lengths (tangential, radial), um: narrow, wide halo
    (400.0, 1000.0),            # wavelength_nm
    (0.0, 40.0),                # incidence, deg
    (None, ALUMINIUM),          # Q = rho_s or the Fresnel factor of aluminium
))


@pytest.mark.parametrize("sigma_nm, lengths, lam_nm, inc_deg, n", GRID)
def test_an_accepted_finish_never_reflects_more_than_falls_on_it(sigma_nm, lengths, lam_nm,
                                                                   inc_deg, n):
    psd = KCorrelation(sigma_nm * 1e-6, 2 * math.pi * lengths[0] * 1e-3,
                       2 * math.pi * lengths[1] * 1e-3, 2.0)
    lam, theta0 = lam_nm * 1e-6, math.radians(inc_deg)
    eps = rr.permittivity(n)
    g = rr.rayleigh_parameter(psd.sigma, lam, theta0)
    if g > rr.MAX_RAYLEIGH:
        with pytest.raises(ConfigError, match="brdf.sigma_nm"):
            rr.check_validity(psd.sigma, lam, theta0, eps, 1.0)
        return
    rr.check_validity(psd.sigma, lam, theta0, eps, 1.0)
    model = rr.specular_halo(rr.RayleighRice(psd, psd.sigma, lam, eps, 1.0), theta0, bins=128)
    # the table reaches where the PSD falls to 1e-4 (B f ~ 22 for C = 2): o_xy within
    # lambda f of the specular direction; twice that, to be sure
    halo = _hemispherical(model, theta0, reach=2 * 25 * lam / min(psd.bx, psd.by))
    total = model.specular_reflectance + halo
    assert total <= 1.0 + 2e-3, (g, model.specular_reflectance, halo)  # rho_s = 1: all the light
    reflectance = 1.0 if eps is None else float(rr.fresnel_unpolarised(eps, math.cos(theta0)))
    assert total <= reflectance * (1 + 3e-3)
    # and the rendered weight is the halo's integral (the table's share of the PSD)
    assert halo == pytest.approx(model.halo_reflectance, rel=0.03, abs=1e-6)


def _rr_config(tmp_path, **brdf):
    d = merge(base_dict(), {
        "brdf": {"__replace__": {"model": "rayleigh_rice", "correlation_length_tangential_um": 12.0,
                                 "correlation_length_radial_um": 5.0, "halo_bins": 64, **brdf}},
        "sampling": {"estimator": "radiometric"}})
    path = tmp_path / "rr.toml"
    _write_toml(path, d)
    return path


@pytest.mark.parametrize("brdf, says", [
    ({"sigma_nm": 3.0, "wavelength_nm": 1.5}, "brdf.sigma_nm"),   # lambda in um by mistake
    ({"sigma_nm": 50.0}, "brdf.sigma_nm"),                        # g = 1.04 at 25 deg
    ({"sigma_nm": 200.0}, "brdf.sigma_nm"),                       # was "lobe off the monitor"
    ({"sigma_nm": 3.0, "refractive_index": [1.0, 0.0]}, "brdf.refractive_index"),
    ({"sigma_nm": 3.0, "refractive_index": [1.0000001, 0.0]}, "brdf.refractive_index"),
])
def test_a_finish_outside_the_first_order_halo_is_refused_through_the_command_line(
        tmp_path, brdf, says):
    cfg = _rr_config(tmp_path, **brdf)
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert res.exit_code == 2, res.output
    assert says in res.output and "Traceback" not in res.output
    if says == "brdf.sigma_nm":
        assert "smooth-surface limit" in res.output and "keep sigma below" in res.output
    else:
        assert "reflects" in res.output and "(n, k)" in res.output
    assert not out.exists() and not list(tmp_path.glob("run.tmp-*"))


def test_a_forced_smooth_regime_of_a_rough_map_is_refused(tmp_path):
    rng = np.random.default_rng(2)
    np.save(tmp_path / "rough.npy", 0.3 * rng.standard_normal((32, 40)))  # um: g ~ 6
    d = merge(base_dict(), {
        "brdf": {"__replace__": {"model": "topography", "file": str(tmp_path / "rough.npy"),
                                 "spacing_mm": [0.001, 0.0015], "regime": "smooth"}},
        "sampling": {"estimator": "radiometric"}})
    _write_toml(tmp_path / "t.toml", d)
    res = CliRunner().invoke(app, ["simulate", str(tmp_path / "t.toml"), "-o",
                                   str(tmp_path / "run"), "--no-figures"])
    assert res.exit_code == 2, res.output
    assert "brdf.regime = 'smooth'" in res.output and "rough.npy" in res.output
    assert "smooth-surface limit" in res.output
