"""Calibration rows (studies/calibration.py): a pure camera-pose error against first-order
geometry, computed here from the law of reflection alone."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import parse_config
from pmdsim.measure.form import FormSpec, remove_form
from pmdsim.measure.reconstruct import prior_frame, reconstruct
from pmdsim.render import Simulation
from pmdsim.studies.calibration import perturbations, rotation_about

from conftest import base_dict, merge

RADIUS = 8.0


def _scene():
    d = merge(base_dict(), {
        "camera": {"resolution": [160, 128], "focal_length_px": 320.0},
        "surface": {"__replace__": {"type": "conic", "aperture": {"shape": "circular", "radius_mm": RADIUS,
                                                                   "centre_mm": [1.2, 2.0]}}},
        "brdf": {"__replace__": {"model": "mirror"}},
    })
    sim = Simulation.from_config(parse_config(d))
    geo = sim.geometry()
    return sim.scene, geo


def _plane_hit(origin, direction, centre, normal):
    t = ((centre - origin) @ normal) / (direction @ normal)
    return origin + t[..., None] * direction


def test_camera_position_error_gives_the_first_order_height_error():
    """The camera assumed 0.3 mm / -0.2 mm off its true place (parallel to the flat part).
    First-order geometry: the node S that the assumed camera C' sees at pixel p is, for the
    true camera, the point S - delta; its decoded monitor point M lies on the reflection of
    the ray direction (S - C') from there; the reconstruction's normal is the bisector of
    S -> C' and S -> M, so the part seems tilted by a slope that is nearly the same
    everywhere; the height error (piston removed) is that tilt from the anchor."""
    scene, geo = _scene()
    u = np.where(geo.surface_mask, geo.specular_u, np.nan)
    v = np.where(geo.surface_mask, geo.specular_v, np.nan)
    cam, mon, surf = scene.camera, scene.monitor, scene.surface
    delta = np.array([0.3, -0.2, 0.0])
    kw = dict(spacing_mm=0.5, anchor="centre", order=4)
    rec0 = reconstruct(u, v, cam, mon, surf, **kw)
    (_, cam1, _, _, _), = [p for p in perturbations("camera_position_mm", 1.0, cam, mon, prior_frame(surf))
                           if p[0] == "x"]
    assert np.allclose(cam1.position - cam.position, [1.0, 0, 0])
    from dataclasses import replace

    rec1 = reconstruct(u, v, replace(cam, position=cam.position + delta), mon, surf, **kw)
    m = rec0.mask & rec1.mask
    assert m.sum() > 500
    x, y = np.meshgrid(rec0.x_mm, rec0.y_mm)
    # first-order prediction at every node (flat part z = 0, normal +z)
    s = np.stack([x[m], y[m], np.zeros(m.sum())], axis=1)
    c1 = cam.position + delta
    a = c1 - s
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    d = s - c1
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = d * np.array([1.0, 1.0, -1.0])  # reflected at the flat part
    mpt = _plane_hit(s - delta, r, mon.centre, mon.normal)
    b = mpt - s
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    n = a + b
    sx_pred, sy_pred = -n[:, 0] / n[:, 2], -n[:, 1] / n[:, 2]
    sx = (rec1.slope_x - rec0.slope_x)[m]
    sy = (rec1.slope_y - rec0.slope_y)[m]
    assert np.sqrt(np.mean(sx_pred**2 + sy_pred**2)) > 3e-4  # a sizeable tilt: ~0.5 mrad
    np.testing.assert_allclose(np.mean(sx), np.mean(sx_pred), rtol=0.05)
    np.testing.assert_allclose(np.mean(sy), np.mean(sy_pred), rtol=0.05)
    # height error, piston removed: the predicted tilt about the anchor
    h_pred = np.full(m.shape, np.nan)
    h_pred[m] = np.mean(sx_pred) * x[m] + np.mean(sy_pred) * y[m]
    spec = FormSpec.of("piston")
    got = remove_form(np.where(m, rec1.height_mm - rec0.height_mm, np.nan), m, x, y, spec).residual
    want = remove_form(h_pred, m, x, y, spec).residual
    rms_got = np.sqrt(np.nanmean(got**2))
    rms_want = np.sqrt(np.nanmean(want**2))
    assert rms_got == pytest.approx(rms_want, rel=0.05)
    assert np.nanmax(np.abs(got - want)) < 0.05 * np.nanmax(np.abs(want))


def test_perturbations_move_one_thing_each():
    scene, _ = _scene()
    cam, mon = scene.camera, scene.monitor
    pf = prior_frame(scene.surface)
    rot = rotation_about([0.0, 0.0, 1.0], np.pi / 2)
    np.testing.assert_allclose(rot @ [1.0, 0, 0], [0, 1.0, 0], atol=1e-15)
    for name, c, mo, p, shift in perturbations("camera_orientation_deg", 0.01, cam, mon, pf):
        np.testing.assert_allclose(c.rotation.T @ c.rotation, np.eye(3), atol=1e-14)
        ang = np.degrees(np.arccos(np.clip((np.trace(c.rotation.T @ cam.rotation) - 1) / 2, -1, 1)))
        assert ang == pytest.approx(0.01, rel=1e-4) and mo is mon
    (_, c, mo, p, shift), = perturbations("surface_distance_mm", 0.05, cam, mon, pf)
    np.testing.assert_allclose(p.centre - pf.centre, 0.05 * pf.rotation[:, 2])
    assert shift == 0.05
    (_, c, mo, p, shift), = perturbations("monitor_pitch_rel", 1e-4, cam, mon, pf)
    assert mo.pitch == pytest.approx(mon.pitch * (1 + 1e-4))
