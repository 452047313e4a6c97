"""Specular peak plus Rayleigh-Rice halo (``pmdsim.brdf.rayleigh_rice``): the BRDF against an
independent implementation of the published formula (and pySCATMECH where it installs),
total integrated scatter against the closed form, the specular share, the halo's tabulated
slope density against the exact BRDF, and a rendered smooth finish (Sq 3 nm)."""

from __future__ import annotations

import cmath
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

from pmdsim.brdf import rayleigh_rice as rr
from pmdsim.brdf.psd import KCorrelation

LAM = 545e-6  # mm
ALUMINIUM = (0.96, 6.69)  # n, k at 545 nm
# anisotropic K-correlation: 3 nm, 12 um tangential (x), 5 um radial (y)
PSD = KCorrelation(3e-6, 2 * math.pi * 12e-3, 2 * math.pi * 5e-3, 2.3)


def _points(n=20, seed=4):
    """n (theta_i, theta_s, phi_s) in rad: incidence 0-60 deg, scattering 0-70 deg, any azimuth."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(0, 1.05, n), rng.uniform(0, 1.2, n), rng.uniform(-math.pi, math.pi, n)], -1)


def _direct_brdf(theta_i, theta_s, phi_s, eps, psd, lam):
    """Rayleigh-Rice BRDF written out per point (Stover, Optical Scattering, eq. 5.15-5.18;
    Elson and Bennett 1979), unpolarised incident light, all polarisations summed."""
    ci, si = math.cos(theta_i), math.sin(theta_i)
    cs, ss = math.cos(theta_s), math.sin(theta_s)
    cp, sp = math.cos(phi_s), math.sin(phi_s)
    ai = cmath.sqrt(eps - si * si)
    as_ = cmath.sqrt(eps - ss * ss)
    qss = abs((eps - 1) * cp / ((ci + ai) * (cs + as_))) ** 2
    qsp = abs((eps - 1) * as_ * sp / ((ci + ai) * (eps * cs + as_))) ** 2
    qps = abs((eps - 1) * ai * sp / ((eps * ci + ai) * (cs + as_))) ** 2
    qpp = abs((eps - 1) * (as_ * ai * cp - eps * si * ss) / ((eps * ci + ai) * (eps * cs + as_))) ** 2
    fx = (ss * cp - si) / lam
    fy = ss * sp / lam
    return 16 * math.pi**2 / lam**4 * ci * cs * 0.5 * (qss + qsp + qps + qpp) * float(psd(fx, fy))


def _local(theta_i, theta_s, phi_s):
    """Local i (towards the camera, azimuth pi so that forward is +x) and o."""
    i = np.array([-math.sin(theta_i), 0.0, math.cos(theta_i)])
    o = np.array([math.sin(theta_s) * math.cos(phi_s), math.sin(theta_s) * math.sin(phi_s), math.cos(theta_s)])
    return i, o


def test_brdf_matches_the_published_formula_at_20_points():
    eps = rr.permittivity(ALUMINIUM)
    m = rr.RayleighRice(PSD, PSD.sigma, LAM, eps)
    for ti, ts, ps in _points():
        i, o = _local(ti, ts, ps)
        want = _direct_brdf(ti, ts, ps, eps, PSD, LAM)
        assert float(m.evaluate(i, o)) == pytest.approx(want, rel=1e-10)
    # and in another azimuth of the plane of incidence (the frame must not matter)
    rot = np.array([[0.6, -0.8, 0], [0.8, 0.6, 0], [0, 0, 1.0]])
    iso = rr.RayleighRice(KCorrelation(3e-6, 0.05, 0.05, 2.3), 3e-6, LAM, eps)
    for ti, ts, ps in _points(5, 9):
        i, o = _local(ti, ts, ps)
        assert float(iso.evaluate(rot @ i, rot @ o)) == pytest.approx(float(iso.evaluate(i, o)), rel=1e-10)


def test_q_is_the_fresnel_reflectance_at_the_specular_direction():
    eps = rr.permittivity(ALUMINIUM)
    m = rr.RayleighRice(PSD, PSD.sigma, LAM, eps)
    for th in (0.0, 0.4, 1.0):
        i = np.array([math.sin(th), 0.0, math.cos(th)])
        o = i * np.array([-1, -1, 1.0])
        assert float(m.q(i, o)) == pytest.approx(float(rr.fresnel_unpolarised(eps, math.cos(th))), rel=1e-12)


REFERENCE = Path(__file__).parents[1] / "data" / "pyscatmech_rayleigh_rice.json"


def _reference_cases():
    return json.loads(REFERENCE.read_text())["cases"]


def _ours(case):
    """pmdsim's Rayleigh-Rice model for a stored case: SCATMECH's ABC PSD A / (1 + (B f)^2)^(C/2)
    (um) is the K-correlation with b = B (in mm) and c = C - 1."""
    b = case["B"] * 1e-3
    psd = KCorrelation(case["sigma_nm"] * 1e-6, b, b, case["C"] - 1)
    return psd, rr.RayleighRice(psd, psd.sigma, case["lambda_um"] * 1e-3, rr.permittivity(tuple(case["nk"])))


@pytest.mark.parametrize("case", _reference_cases(), ids=lambda c: c["name"])
def test_brdf_matches_pyscatmech(case):
    """pySCATMECH's Microroughness_BRDF_Model (first-order vector perturbation, NIST) at 20
    points per case within 1 %: two metals and wavelengths, an isotropic K-correlation PSD
    (SCATMECH has no anisotropic one), unpolarised incident light, all polarisations detected
    (the Mueller matrix's M00). The values were computed by pySCATMECH 0.1.10 with
    ``tools/pyscatmech_reference.py`` (it builds from C++ source, too long for CI);
    ``test_stored_values_are_pyscatmech`` re-evaluates them where it is installed."""
    psd, ours = _ours(case)
    assert psd.a * 1e12 == pytest.approx(case["A"], rel=1e-12)  # the same PSD normalisation
    rel = []
    for (ti, ts, ps), want in zip(case["points_rad"], case["brdf_per_sr"]):
        i, o = _local(ti, ts, ps)
        rel.append(float(ours.evaluate(i, o)) / want - 1)
    assert len(rel) == 20 and max(abs(r) for r in rel) < 0.01, rel


def test_stored_values_are_pyscatmech():
    pytest.importorskip("pySCATMECH")
    from pySCATMECH.brdf import BRDF_Model

    for case in _reference_cases():
        theirs = BRDF_Model("Microroughness_BRDF_Model", {
            "lambda": case["lambda_um"], "substrate": f"({case['nk'][0]},{case['nk'][1]})",
            "psd": "ABC_PSD_Function", "psd.A": case["A"], "psd.B": case["B"], "psd.C": case["C"]})
        for (ti, ts, ps), want in zip(case["points_rad"], case["brdf_per_sr"]):
            assert theirs.BRDF(ti, ts, ps) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("theta_i_deg", [0.0, 30.0])
def test_total_integrated_scatter_matches_the_closed_form(theta_i_deg):
    """Q = R (scalar form) and a PSD narrow against 1/lambda: the hemispherical integral of
    f cos(theta_s) is R (4 pi sigma cos(theta_i) / lambda)^2 within 1 % (SciPy quadrature
    over the spatial frequencies: cos(theta_s) d omega = lambda^2 dfx dfy)."""
    psd = KCorrelation(2e-6, 2 * math.pi * 40e-3, 2 * math.pi * 25e-3, 3.0)
    m = rr.RayleighRice(psd, psd.sigma, LAM, None, rho_s=0.8)
    ti = math.radians(theta_i_deg)
    i = np.array([-math.sin(ti), 0.0, math.cos(ti)])

    def f(r, t):  # polar spatial frequency about the specular direction, r in 1/mm
        fx, fy = r * math.cos(t), r * math.sin(t)
        o = np.array([math.sin(ti) + LAM * fx, LAM * fy, 0.0])
        o2 = 1 - o[0] ** 2 - o[1] ** 2
        if o2 <= 0:
            return 0.0
        o[2] = math.sqrt(o2)
        return float(m.evaluate(i, o)) * LAM**2 * r

    r_knee = 1 / psd.by
    tis = 0.0
    for lo, hi in ((0, r_knee), (r_knee, 30 * r_knee), (30 * r_knee, 1 / LAM)):
        tis += integrate.dblquad(lambda r, t: f(r, t), 0, 2 * math.pi, lo, hi, epsabs=0, epsrel=1e-6)[0]
    closed = 0.8 * (4 * math.pi * psd.sigma * math.cos(ti) / LAM) ** 2
    assert tis == pytest.approx(closed, rel=0.01)


def test_specular_share_is_the_closed_form():
    eps = rr.permittivity(ALUMINIUM)
    m = rr.RayleighRice(PSD, PSD.sigma, LAM, eps)
    for th in (0.0, 0.3, 0.9):
        c = math.cos(th)
        share = math.exp(-(4 * math.pi * PSD.sigma * c / LAM) ** 2)
        # NumPy's and the C library's exp may differ in the last place (NumPy 2.4)
        assert float(rr.specular_share(PSD.sigma, LAM, c)) == pytest.approx(share, rel=4e-16)
        assert float(m.specular(c)) == pytest.approx(float(rr.fresnel_unpolarised(eps, c)) * share, rel=1e-14)
    model = rr.specular_halo(m, math.radians(25.0))
    c0 = math.cos(math.radians(25.0))
    assert model.specular_reflectance == pytest.approx(
        float(rr.fresnel_unpolarised(eps, c0)) * math.exp(-(4 * math.pi * PSD.sigma * c0 / LAM) ** 2), rel=1e-14)


def test_halo_table_approximates_the_exact_brdf_near_the_specular_direction():
    """The rendered halo (a tabulated slope density built for theta_0 = 25 deg) against the
    exact Rayleigh-Rice BRDF at theta_0 out to 0.1 rad from the specular direction, both
    axes: within 4 % (the cell size, cos factors and Q's angular change); the halo's
    reflectance is R (1 - exp(-(4 pi sigma cos / lambda)^2)) (R g^2 to first order; with
    the peak's R exp(-g^2) never more than R) times the share of the PSD in the table."""
    eps = rr.permittivity(ALUMINIUM)
    exact = rr.RayleighRice(PSD, PSD.sigma, LAM, eps)
    th0 = math.radians(25.0)
    model = rr.specular_halo(exact, th0, bins=1024)
    i = np.array([math.sin(th0), 0.0, math.cos(th0)])
    spec = i * np.array([-1, -1, 1.0])
    ratios = []
    for d in (0.003, 0.01, 0.03, 0.1):
        for ax in ((1, 0), (0, 1), (0.6, -0.8)):
            o = spec + d * np.array([ax[0] * math.cos(th0), ax[1], ax[0] * math.sin(th0)])
            o /= np.linalg.norm(o)
            ratios.append(float(model.evaluate(i, o)) / float(exact.evaluate(i, o)))
    assert np.all(np.abs(np.array(ratios) - 1) < 0.04), ratios
    r0 = float(rr.fresnel_unpolarised(eps, math.cos(th0)))
    g2 = (4 * math.pi * PSD.sigma * math.cos(th0) / LAM) ** 2
    assert model.halo_reflectance == pytest.approx(r0 * -math.expm1(-g2) * model.table_share, rel=1e-12)
    assert 0.9 < model.table_share <= 1.0


def test_smooth_finish_renders_peak_plus_halo():
    """Sq 3 nm at 545 nm, 25 deg (specular share 0.991): rendered as the mirror plus the
    halo (radiometric estimator, continuous monitor). Fringes of 2 monitor px are far
    narrower than the halo, which then only adds light: the modulation falls by the halo's
    share h / (a + h) (a the peak's, h the halo's reflectance) within 5 % of itself (the
    halo's residual fringe and what misses the monitor), the phase is the mirror's to
    < 1 mrad; the lobe pass's mean weight is h; the paper estimator is refused."""

    from conftest import make_config
    from pmdsim.config import ConfigError
    from pmdsim.render import Simulation

    brdf = {"__replace__": dict(model="rayleigh_rice", sigma_nm=3.0, correlation_length_tangential_um=12.0,
                                correlation_length_radial_um=5.0, exponent_c=2.3, rho_s=0.9, halo_bins=128)}
    cam = {"resolution": [20, 16], "focal_length_px": 40.0}
    cfg = make_config(brdf=brdf, sampling={"n_rays": 64, "estimator": "radiometric", "mode": "stratified"},
                      monitor={"pixel_model": "continuous"}, camera=cam)
    sim = Simulation.from_config(cfg)
    b = sim.scene.brdf
    a, h = b.specular_reflectance, b.halo_reflectance
    assert b.theta0 == pytest.approx(math.radians(25.0), abs=0.02)  # the set-up's incidence
    ref = Simulation(sim.scene.specular(), 8, "threads", 2)
    fr = sim.render_fringes((2.0,), ("x", "y"), 4)
    fm = ref.render_fringes((2.0,), ("x", "y"), 4)
    for d in range(2):
        s, m = fr.sums[d, 0], fm.sums[d, 0]
        ok = np.isfinite(s) & np.isfinite(m) & (np.abs(m) > 0.5)
        assert ok.sum() > 100
        loss = 1 - np.abs(s[ok]) / fr.f_hit[ok]
        assert np.median(loss) == pytest.approx(h / (a + h), rel=0.05)
        assert np.abs(np.angle(s[ok] / m[ok])).max() < 1e-3
    assert np.median(fr.f_total[np.isfinite(fr.f_total)]) - a == pytest.approx(h, rel=0.01)
    # randomised QMC replicates leave more of the halo's fringe, but within the error they report
    rule = Simulation.from_config(make_config(brdf=brdf, sampling={"n_rays": 64, "estimator": "radiometric",
                                                                   "mode": "rqmc"},
                                              monitor={"pixel_model": "continuous"}, camera=cam))
    fq = rule.render_fringes((2.0,), ("y",), 4)
    s, e = fq.sums[0, 0], fq.sums_err[0, 0]
    ok = np.isfinite(s) & (fq.f_hit > 0.999 * (a + h))
    assert ok.sum() > 100
    assert np.all(np.abs(np.abs(s[ok]) - a) <= 2 * np.abs(e[ok]) + 1e-12)
    # weighted_mean (solid-angle cone: the polar scheme weighs the centre, where the halo keeps
    # the fringe): peak and halo weighed by their reflectances, about the same loss (10 %:
    # the 4 deg cone drops the halo's far tail, so its centre's residual fringe weighs more)
    wm = make_config(brdf=brdf, sampling={"n_rays": 400, "estimator": "weighted_mean", "theta_max_deg": 4.0,
                                           "scheme": "solid_angle"},
                     monitor={"pixel_model": "continuous"}, camera={"resolution": [20, 16], "focal_length_px": 40.0})
    fw = Simulation.from_config(wm).render_fringes((2.0,), ("y",), 4)
    s, m = fw.sums[0, 0], fm.sums[1, 0]
    ok = np.isfinite(s) & np.isfinite(m) & (np.abs(m) > 0.5) & (fw.f_hit > 0.999)
    assert np.median(1 - np.abs(s[ok])) == pytest.approx(h / (a + h), rel=0.1)
    paper = make_config(brdf=brdf, sampling={"n_rays": 16, "estimator": "paper"})
    with pytest.raises(ConfigError, match="sampling.estimator"):
        Simulation.from_config(paper).render_fringes((20.0,), ("x",), 4)


def test_diagnostics_count_the_specular_peak():
    """The diagnostics sample the halo alone; with the peak the modulation is
    (a + h m) / (a + h) and the phase error the halo's times h m / (a + h m)."""
    from conftest import make_config
    from pmdsim.render import Simulation
    from pmdsim.studies.diagnostics import diagnose

    brdf = {"__replace__": dict(model="rayleigh_rice", sigma_nm=3.0, correlation_length_tangential_um=12.0,
                                correlation_length_radial_um=5.0, rho_s=0.9, halo_bins=64)}
    cfg = make_config(brdf=brdf, sampling={"n_rays": 32, "estimator": "radiometric"},
                      camera={"resolution": [20, 16], "focal_length_px": 40.0})
    sim = Simulation.from_config(cfg)
    d = diagnose(sim, widths=(4.0,), directions=("y",), grid=(3, 3), phase_method="delta")
    halo = diagnose(Simulation(sim.scene.replace(brdf=sim.scene.brdf.halo), 8, "threads", 2),
                    widths=(4.0,), directions=("y",), grid=(3, 3), phase_method="delta")
    a, h = sim.scene.brdf.specular_reflectance, sim.scene.brdf.halo_reflectance
    m = halo.rays.modulation
    np.testing.assert_allclose(d.rays.modulation, (a + h * m) / (a + h), rtol=1e-12)
    np.testing.assert_allclose(d.phase_se, halo.phase_se * h * m / (a + h * m), rtol=1e-12)
    assert np.nanmedian(d.rays.modulation) > 0.99
