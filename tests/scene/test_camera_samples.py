"""The camera's sample sets, checked for their symmetry and moments against closed forms:
the sub-pixel grid (a pixel's footprint) and the thin lens's aperture points (antithetic
pairs on the disk, Shirley-Chiu's area-preserving map)."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.scene.camera import Camera, concentric_disk


def _camera(subpixels=1, aperture_mm=None, samples=16, seed=0, width=7):
    return Camera(width, 5, 50.0, (3.2, 1.9), np.zeros(3), np.eye(3), subpixels=subpixels,
                  aperture_mm=aperture_mm, focus_distance_mm=300.0, aperture_samples=samples,
                  aperture_seed=seed)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
def test_subpixel_grid_is_centred_symmetric_with_the_pixel_moments(n):
    """n x n cell centres: mean 0 (the set is its own mirror image through the pixel
    centre), per-axis variance (n^2 - 1) / (12 n^2) (a uniform pixel: 1/12 as n grows), no
    correlation, inside the pixel."""
    off = _camera(subpixels=n).subpixel_offsets()
    assert off.shape == (n * n, 2)
    mirrored = {tuple(np.round(-p, 12)) for p in off}
    assert mirrored == {tuple(np.round(p, 12)) for p in off}
    np.testing.assert_allclose(off.mean(0), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.mean(off**2, axis=0), (n * n - 1) / (12 * n * n), rtol=1e-12)
    assert abs(np.mean(off[:, 0] * off[:, 1])) < 1e-15
    assert np.all(np.abs(off) < 0.5)
    # every column offset appears n times (a product grid: d_col with every d_row)
    cols, counts = np.unique(np.round(off[:, 0], 12), return_counts=True)
    assert cols.size == n and np.all(counts == n)


@pytest.mark.parametrize("m", [2, 9, 16, 33])
def test_aperture_points_are_antithetic_and_on_the_disk(m):
    cam = _camera(aperture_mm=8.0, samples=m, seed=11)
    pts = cam.aperture_points(3, cam.width)  # (W, m, 2)
    assert pts.shape == (cam.width, m, 2)
    half = m // 2
    np.testing.assert_array_equal(pts[:, half:2 * half], -pts[:, :half])  # A and -A
    if m % 2:
        np.testing.assert_array_equal(pts[:, -1], 0.0)  # odd: the lens centre
    np.testing.assert_allclose(pts.mean(1), 0.0, atol=1e-15)  # centroid on the chief ray
    assert np.hypot(pts[..., 0], pts[..., 1]).max() <= 4.0 + 1e-12
    # seeded per camera row: the same row repeats, another row differs, pixels differ
    np.testing.assert_array_equal(pts, cam.aperture_points(3, cam.width))
    assert not np.allclose(pts, cam.aperture_points(4, cam.width))
    assert not np.allclose(pts[0], pts[1])


def test_aperture_points_have_the_moments_of_the_uniform_disk():
    """Radius R: E[x^2] = E[y^2] = R^2/4, E[xy] = 0, E[r^2] = R^2/2, P(r < R/2) = 1/4,
    over many pixels' shifted lattices (each pixel's set is a shifted lattice: unbiased)."""
    r_ap = 3.0
    cam = _camera(aperture_mm=2 * r_ap, samples=64, seed=2, width=400)
    pts = np.concatenate([cam.aperture_points(r, cam.width) for r in range(10)]).reshape(-1, 2)
    x, y = pts[:, 0], pts[:, 1]
    assert np.mean(x * x) == pytest.approx(r_ap**2 / 4, rel=0.01)
    assert np.mean(y * y) == pytest.approx(r_ap**2 / 4, rel=0.01)
    assert abs(np.mean(x * y)) < 0.005 * r_ap**2
    assert np.mean(x * x + y * y) == pytest.approx(r_ap**2 / 2, rel=0.01)
    assert np.mean(np.hypot(x, y) < r_ap / 2) == pytest.approx(0.25, abs=0.01)
    # a single pixel's 64 points are a lattice, far better than 64 random points
    one = cam.aperture_points(0, cam.width)[5]
    assert np.mean(np.sum(one**2, axis=1)) == pytest.approx(r_ap**2 / 2, rel=0.05)


def test_concentric_map_preserves_area_quadrant_by_quadrant():
    """The map of a regular grid of cell centres: each quadrant of the square goes to one
    quadrant of the disk, and equal areas stay equal (the share of the points within
    radius rho is rho^2)."""
    g = (np.arange(400) + 0.5) / 400
    u1, u2 = np.meshgrid(g, g)
    x, y = concentric_disk(u1.ravel(), u2.ravel())
    q_sq = (u1.ravel() > 0.5).astype(int) * 2 + (u2.ravel() > 0.5)
    q_disk = (x > 0).astype(int) * 2 + (y > 0)
    np.testing.assert_array_equal(q_sq, q_disk)
    r = np.hypot(x, y)
    for rho in (0.3, 0.6, 0.9):
        assert np.mean(r < rho) == pytest.approx(rho**2, abs=2e-3)


def test_pinhole_sends_the_chief_ray_only():
    cam = _camera()
    np.testing.assert_array_equal(cam.aperture_points(0, cam.width), 0.0)
    assert cam.rays_per_pixel == 1
    assert _camera(subpixels=3, aperture_mm=4.0, samples=6).rays_per_pixel == 54
