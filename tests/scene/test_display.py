"""Display physics: response (gamma, LUT, quantisation, pre-compensation) and the per-ray
geometry of the emitting surface (cover glass, flatness), each against a closed form or an
independent computation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, optimize

from pmdsim.config import ConfigError, parse_config
from pmdsim.kernels import bundle as kb
from pmdsim.scene.display import DisplayGeometry, DisplayResponse, read_response_lut

from conftest import base_dict

K = 4
DELTAS = 2 * np.pi * np.arange(K) / K


def _decode_error(resp: DisplayResponse, phi: np.ndarray, k: int = K) -> np.ndarray:
    d = 2 * np.pi * np.arange(k) / k
    frames = resp.luminance(0.5 + 0.5 * np.cos(phi[None] + d[:, None]))
    z = np.tensordot(np.exp(-1j * d), frames, axes=1)
    return np.angle(z * np.exp(-1j * phi))


def _harmonics(gamma: float, m_max: int = 8) -> np.ndarray:
    """a_m of (0.5 + 0.5 cos t)^gamma = sum a_m cos(m t), by quadrature."""
    f = lambda t, m: (0.5 + 0.5 * np.cos(t)) ** gamma * np.cos(m * t)  # noqa: E731
    a = np.array([integrate.quad(f, 0, np.pi, args=(m,), limit=200)[0] / np.pi for m in range(m_max + 1)])
    a[1:] *= 2
    return a


def test_gamma_4step_error_is_the_4phi_harmonic():
    """K = 4: harmonics 3 and 5 alias onto the fundamental, phase error
    ~ (a5 - a3) / a1 sin(4 phi) to first order."""
    resp = DisplayResponse(gamma=2.2)
    phi = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    err = _decode_error(resp, phi)
    measured = 2 * np.mean(err * np.sin(4 * phi))
    a = _harmonics(2.2)
    expect = (a[5] - a[3]) / a[1]
    assert measured == pytest.approx(expect, rel=0.05)
    assert abs(expect) > 5e-3  # a real effect (about 10 mrad, PHYSICS.md)
    # nothing at the other low harmonics
    assert abs(2 * np.mean(err * np.cos(4 * phi))) < 1e-3 * abs(expect) + 1e-12


def test_precompensated_gamma_vanishes_and_quantisation_stays_in_bound():
    phi = np.linspace(-np.pi, np.pi, 3601)
    exact = DisplayResponse(gamma=2.2, precompensate=True)
    assert np.max(np.abs(_decode_error(exact, phi))) < 1e-3
    for bits in (8, 10):
        resp = DisplayResponse(gamma=2.2, precompensate=True, bit_depth=bits)
        err = _decode_error(resp, phi)
        # luminance error per frame <= max r'(d) * step / 2 = gamma / (2 (2^b - 1)); phase
        # error <= 2 / (K B) * sum_k |dL_k| |sin| <= 2 sqrt(2) max|dL| with B = 1/2
        bound = 2 * np.sqrt(2) * 2.2 / (2 * (2**bits - 1))
        assert np.max(np.abs(err)) <= bound
        assert np.max(np.abs(err)) > bound / 50  # quantisation is visible


def test_more_steps_suppress_gamma():
    phi = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    resp = DisplayResponse(gamma=2.2)
    e4 = np.max(np.abs(_decode_error(resp, phi, 4)))
    e8 = np.max(np.abs(_decode_error(resp, phi, 8)))
    a = _harmonics(2.2, 10)
    assert e8 < e4 / 10
    assert e8 == pytest.approx(abs(a[7] - a[9]) / a[1], rel=0.2)


def test_lut_matches_gamma(tmp_path):
    d = np.linspace(0, 1, 256)
    path = tmp_path / "lut.csv"
    path.write_text("drive,luminance\n" + "\n".join(f"{x * 255:.0f},{0.3 + 200 * x**2.2:.9f}" for x in d))
    ld, ll = read_response_lut(path)
    lut = DisplayResponse(lut_drive=ld, lut_luminance=ll)
    x = np.linspace(0, 1, 101)
    np.testing.assert_allclose(lut.response(x), x**2.2, atol=2e-4)
    np.testing.assert_allclose(lut.response(lut.inverse_response(x)), x, atol=1e-9)
    assert not lut.is_linear


def _rows(theta, phi, dist=100.0, pitch=0.25, size=(4000, 3000)):
    """Synthetic geometry rows and nominal hits: a surface point ``dist`` mm in front of the
    monitor centre, rays at incidence theta, azimuth phi (in the monitor frame)."""
    g = np.zeros(kb.G_SIZE)
    g[kb.G_T] = -dist
    g[kb.G_U0] = (size[0] - 1) / 2
    g[kb.G_V0] = (size[1] - 1) / 2
    u = g[kb.G_U0] + dist * np.tan(theta) * np.cos(phi) / pitch
    v = g[kb.G_V0] + dist * np.tan(theta) * np.sin(phi) / pitch
    return g, u, v


def _kernel_hits(geom: DisplayGeometry, theta, phi, pitch=0.25, size=(4000, 3000)):
    g, u, v = _rows(theta, phi, pitch=pitch, size=size)
    n = u.size
    ub, vb = u.copy(), v.copy()
    iu = np.floor(ub + 0.5).astype(np.int64)
    iv = np.floor(vb + 0.5).astype(np.int64)
    f = np.ones(n)
    mc = geom.kernel_params(pitch, size[0], size[1])
    kb.monitor_correction(g, mc, n, size[0], size[1], ub, vb, iu, iv, f)
    return u, v, ub, vb, f


def test_cover_glass_shift_matches_snell():
    theta = np.radians(np.array([0.0, 5.0, 20.0, 35.0, 50.0, 65.0]))
    phi = np.radians(np.array([0.0, 30.0, 100.0, 200.0, 290.0, 45.0]))
    t, n = 1.1, 1.52
    pitch = 0.25
    u, v, ug, vg, _ = _kernel_hits(DisplayGeometry(glass_thickness=t, glass_index=n), theta, phi, pitch)
    # independent: vector Snell refraction at the glass front (plane at height t), then on to
    # the pixel plane; the shift relative to the straight ray
    for k in range(theta.size):
        d = np.array([np.sin(theta[k]) * np.cos(phi[k]), np.sin(theta[k]) * np.sin(phi[k]), -np.cos(theta[k])])
        normal = np.array([0.0, 0.0, 1.0])
        eta = 1.0 / n
        ci = -d @ normal
        tr = eta * d + (eta * ci - np.sqrt(1 - eta**2 * (1 - ci**2))) * normal
        entry = -d * (t / d[2])  # straight ray reaches z = 0 at the origin; entry at z = t
        entry = -d * t / -d[2]
        hit = entry + tr * (-entry[2] / tr[2])
        shift_mm = hit[:2]
        got = np.array([ug[k] - u[k], vg[k] - v[k]]) * pitch
        np.testing.assert_allclose(got, shift_mm, atol=1e-9)
        # the closed form of the issue: |shift| = t (tan theta - tan theta_r)
        th_r = np.arcsin(np.sin(theta[k]) / n)
        assert np.hypot(*got) == pytest.approx(t * (np.tan(theta[k]) - np.tan(th_r)), abs=1e-9)
        np.testing.assert_allclose(np.hypot(*got), DisplayGeometry(t, n).glass_shift(theta[k]), atol=1e-12)


def test_flatness_hit_matches_root_finding():
    c = np.zeros((3, 3))
    c[0, 0] = 0.3  # piston, mm
    c[2, 0] = 2e-4  # bow along x, mm / mm^2
    c[1, 1] = -5e-5
    geom = DisplayGeometry(flatness=c)
    theta = np.radians(np.array([10.0, 25.0, 40.0]))
    phi = np.radians(np.array([0.0, 60.0, 170.0]))
    pitch = 0.25
    size = (4000, 3000)
    u, v, ub, vb, _ = _kernel_hits(geom, theta, phi, pitch, size)
    uc, vc = (size[0] - 1) / 2, (size[1] - 1) / 2
    for k in range(theta.size):
        d = np.array([np.sin(theta[k]) * np.cos(phi[k]), np.sin(theta[k]) * np.sin(phi[k]), -np.cos(theta[k])])
        p0 = np.array([(u[k] - uc) * pitch, (v[k] - vc) * pitch, 0.0])  # nominal plane hit
        h = lambda s: (p0 + s * d)[2] - geom.height(*(p0 + s * d)[:2])  # noqa: E731
        s = optimize.brentq(h, -50, 50, xtol=1e-14)
        hit = p0 + s * d
        np.testing.assert_allclose([(ub[k] - uc) * pitch, (vb[k] - vc) * pitch], hit[:2], atol=1e-9)
    # piston alone: the closed form -h tan(theta) along the ray's azimuth
    geom = DisplayGeometry(flatness=np.array([[0.3]]))
    u, v, ub, vb, _ = _kernel_hits(geom, theta, phi, pitch, size)
    np.testing.assert_allclose(np.hypot(ub - u, vb - v) * pitch, 0.3 * np.tan(theta), atol=1e-12)


def test_falloff_weights():
    geom = DisplayGeometry(falloff_exponent=2.0, falloff_table=np.array([[0.0, 1.0], [60.0, 0.5]]))
    theta = np.radians(np.array([0.0, 30.0, 45.0]))
    *_, f = _kernel_hits(geom, theta, np.zeros(3))
    np.testing.assert_allclose(f, np.cos(theta) ** 2 * (1 - 0.5 * np.degrees(theta) / 60), rtol=1e-6)
    np.testing.assert_allclose(f, geom.falloff(theta), rtol=1e-6)


def test_monitor_config_fields():
    d = base_dict()
    d["monitor"].update(bit_depth=8, precompensate_gamma=True, gamma=2.2,
                        cover_glass_thickness_mm=1.0, flatness_coefficients_mm=[[0.1, 0], [0, 0]])
    cfg = parse_config(d)
    from pmdsim.scene import Monitor

    mon = Monitor.from_config(cfg.monitor)
    assert not mon.is_linear and mon.correction_params() is not None
    d["monitor"]["flatness_coefficients_mm"] = [[0.1, 0]]
    with pytest.raises(ConfigError, match="flatness_coefficients_mm"):
        parse_config(d)


def test_height_map_hit_matches_root_finding(tmp_path):
    """A measured height map (bilinear between nodes) moves the hit to where the ray meets
    it; the reference interpolates with SciPy and finds the root with brentq."""
    rng = np.random.default_rng(2)
    hmap = 0.2 * rng.standard_normal((7, 9))  # mm, a coarse, bumpy grid
    path = tmp_path / "h.npy"
    np.save(path, hmap)
    from pmdsim.scene.display import read_height_map

    size = (400, 300)
    pitch = 0.5
    geom = DisplayGeometry(height_map=read_height_map(path), monitor_size=size)
    theta = np.radians(np.array([5.0, 20.0, 35.0, 30.0]))
    phi = np.radians(np.array([10.0, 100.0, 220.0, 300.0]))
    u, v, ub, vb, _ = _kernel_hits(geom, theta, phi, pitch, size)
    uc, vc = (size[0] - 1) / 2, (size[1] - 1) / 2
    for k in range(theta.size):
        d = np.array([np.sin(theta[k]) * np.cos(phi[k]), np.sin(theta[k]) * np.sin(phi[k]), -np.cos(theta[k])])
        p0 = np.array([(u[k] - uc) * pitch, (v[k] - vc) * pitch, 0.0])
        h = lambda s: (p0 + s * d)[2] - geom.height(*(p0 + s * d)[:2], pitch=pitch)  # noqa: E731
        s = optimize.brentq(h, -5, 5, xtol=1e-14)
        hit = p0 + s * d
        np.testing.assert_allclose([(ub[k] - uc) * pitch, (vb[k] - vc) * pitch], hit[:2], atol=1e-9)
        assert np.hypot(*(hit[:2] - p0[:2])) > 1e-3
