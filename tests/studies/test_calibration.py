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


# =========================================================================== each component alone
def _calibration_case():
    """A concave mirror (R 200 mm, off-centre circular aperture) seen by an off-axis camera:
    its exact monitor coordinates as the ideal decoding, and the budget's calibration rows
    with a distinct uncertainty per group."""
    from pmdsim.studies.height_rows import Decoded, form_spec, reconstruct_decoded

    d = merge(base_dict(), {
        "camera": {"resolution": [64, 52], "focal_length_px": 134.0,
                   "principal_point_px": [33.3, 24.8]},
        "surface": {"__replace__": {"type": "conic", "radius_mm": -200.0,
                                    "aperture": {"shape": "circular", "radius_mm": RADIUS,
                                                 "centre_mm": [1.2, 2.0]}}},
        "brdf": {"__replace__": {"model": "mirror"}},
        "reconstruct": {"spacing_mm": 1.0, "remove": "piston"},
        "budget": {"calibration": {"camera_position_mm": 0.07, "camera_orientation_deg": 0.004,
                                   "principal_point_px": 0.3, "monitor_position_mm": 0.09,
                                   "monitor_orientation_deg": 0.006, "focal_length_rel": 0.0,
                                   "distortion_k1": 0.0, "monitor_pitch_rel": 0.0,
                                   "surface_distance_mm": 0.0}},
    })
    cfg = parse_config(d)
    sim = Simulation.from_config(cfg)
    geo = sim.geometry()
    ok = geo.surface_mask & np.isfinite(geo.specular_u) & np.isfinite(geo.specular_v)
    dec = Decoded({"x": np.where(ok, geo.specular_u, np.nan), "y": np.where(ok, geo.specular_v, np.nan)},
                  {"x": ok, "y": ok}, 0.0)
    rec0 = reconstruct_decoded(cfg, sim.scene, dec)
    return cfg, sim.scene, dec, rec0, form_spec(cfg)


def _own_perturbation(group, component, sigma, cam, mon):
    """The calibration off by ``sigma`` in one component, built here (SciPy rotations),
    not by :func:`perturbations`."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    axis = {"x": 0, "y": 1, "z": 2}
    if group == "camera_position_mm":
        return replace(cam, position=cam.position + sigma * np.eye(3)[axis[component]]), mon
    if group == "camera_orientation_deg":  # about the camera's own axis: R Rot(e_k)
        k = axis[component.split()[-1]]
        return replace(cam, rotation=cam.rotation @ Rotation.from_rotvec(
            np.radians(sigma) * np.eye(3)[k]).as_matrix()), mon
    if group == "principal_point_px":
        c0, r0 = cam.principal_point
        return replace(cam, principal_point=(c0 + sigma, r0) if component == "col"
                       else (c0, r0 + sigma)), mon
    if group == "monitor_position_mm":
        return cam, replace(mon, centre=mon.centre + sigma * np.eye(3)[axis[component]])
    if group == "monitor_orientation_deg":
        ax = {"about its columns (e_u)": mon.e_u, "about its rows (e_v)": mon.e_v,
              "about its normal": mon.normal}[component]
        r = Rotation.from_rotvec(np.radians(sigma) * ax / np.linalg.norm(ax)).as_matrix()
        return cam, replace(mon, e_u=r @ mon.e_u, e_v=r @ mon.e_v, normal=r @ mon.normal)
    raise AssertionError(group)


def test_each_calibration_component_against_a_central_difference():
    """Every component row (camera position x/y/z, camera rotation about its own x/y/z,
    principal point column and row separately, monitor position x/y/z, monitor rotation
    about e_u/e_v/normal) equals the central difference (rec(+s) - rec(-s)) / 2 of
    reconstructions with the calibration perturbed here: slope RMS X and Y and the height
    RMS after piston removal, within the second-order terms (2 %). A component applied
    to another axis (column for row, world for camera axis, x for y) moves the other
    slope or another amount and fails."""
    from pmdsim.measure.form import remove_form
    from pmdsim.studies.height_rows import reconstruct_decoded
    from pmdsim.studies.calibration import calibration_rows

    cfg, scene, dec, rec0, spec = _calibration_case()
    rows = {r["effect"]: r for r in calibration_rows(cfg, scene, dec, rec0, spec, (None, None))}
    unc = cfg.budget.calibration
    expected_components = {
        "camera_position_mm": ["x", "y", "z"],
        "camera_orientation_deg": ["about camera x", "about camera y", "about camera z"],
        "principal_point_px": ["col", "row"],
        "monitor_position_mm": ["x", "y", "z"],
        "monitor_orientation_deg": ["about its columns (e_u)", "about its rows (e_v)",
                                    "about its normal"],
    }
    assert set(rows) == set(expected_components) | {"calibration_total"}
    cam, mon = scene.camera, scene.monitor
    seen = {}
    for group, names in expected_components.items():
        comps = rows[group]["components"]
        assert [c["label"] for c in comps] == names
        sigma = float(getattr(unc, group))
        for comp in comps:
            recs = [reconstruct_decoded(cfg, scene, dec, *_own_perturbation(group, comp["label"], s, cam, mon))
                    for s in (sigma, -sigma)]
            x, y = np.meshgrid(rec0.x_mm, rec0.y_mm)

            def stats(d_sx, d_sy, d_h, m):
                hr = remove_form(np.where(m, d_h, np.nan), m, x, y, spec).residual[m] * 1e6
                return (np.sqrt(np.mean((d_sx[m] * 1e6) ** 2)),
                        np.sqrt(np.mean((d_sy[m] * 1e6) ** 2)), np.sqrt(np.nanmean(hr**2)))

            # the row is the +1 sigma difference, here from the calibration built here ...
            mf = recs[0].mask & rec0.mask
            forward = stats(recs[0].slope_x - rec0.slope_x, recs[0].slope_y - rec0.slope_y,
                            recs[0].height_mm - rec0.height_mm, mf)
            got = (comp["slope_rms_x_urad"], comp["slope_rms_y_urad"], comp["height_rms_nm"])
            for w, g, what in zip(forward, got, ("slope x", "slope y", "height")):
                assert g == pytest.approx(w, rel=1e-6, abs=1e-9), (group, comp["label"], what)
            # ... and sensitivity x uncertainty: the central difference on the nodes all three
            # share agrees with that +1 sigma difference to the second-order terms
            m = mf & recs[1].mask
            assert m.sum() > 100
            central = stats(0.5 * (recs[0].slope_x - recs[1].slope_x),
                            0.5 * (recs[0].slope_y - recs[1].slope_y),
                            0.5 * (recs[0].height_mm - recs[1].height_mm), m)
            fwd = stats(recs[0].slope_x - rec0.slope_x, recs[0].slope_y - rec0.slope_y,
                        recs[0].height_mm - rec0.height_mm, m)
            for c, f, what in zip(central, fwd, ("slope x", "slope y", "height")):
                assert f == pytest.approx(c, rel=0.03, abs=1e-3 * max(central)), (group, comp["label"], what)
            seen[(group, comp["label"])] = got
        # the group row: its components in quadrature
        for k in ("slope_rms_x_urad", "slope_rms_y_urad", "height_rms_nm"):
            assert rows[group][k] == pytest.approx(np.sqrt(sum(c[k] ** 2 for c in comps)), rel=1e-12)
    # the components are not interchangeable: column and row, and the axes, differ
    pp = seen[("principal_point_px", "col")], seen[("principal_point_px", "row")]
    assert pp[0][0] > 2 * pp[0][1] and pp[1][1] > 2 * pp[1][0]  # col: x slope; row: y slope
