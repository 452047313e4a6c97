"""Text summaries of a run: the measurement chain's table and the diagnostics account
(``summary.txt``), warning lines as the command line prints them."""

from __future__ import annotations

import math

import os


def _num(v, digits=4) -> str:
    if v is None:
        return "nan"
    if isinstance(v, int):
        return str(v)
    return f"{v:.{digits}g}"


def summary_text(stats: dict, timings: dict | None = None) -> str:
    """A short human-readable summary of :func:`statistics` (for ``summary.txt``)."""
    lines = [f"pmdsim measurement chain: {stats['name']}",
             f"decoding: {stats['method']} unwrapping, widths {stats['widths_px']} monitor px, "
             f"K = {stats['shifts']} shifts; deviation of the finest width "
             f"({stats['finest_width_px']:g} px) from the ideal specular reference",
             f"pixels masked when the modulation ratio < {stats['min_modulation_ratio']:g} "
             "(counted below, never hidden)"]
    smp = stats.get("sampling")
    if smp:
        line = f"sampling: {smp.get('mode')}, {smp.get('rule')} ({smp.get('nodes')} nodes"
        if smp.get("error") == "embedded":
            line += f"; numerical error from the embedded {smp.get('embedded_rule')}"
        elif smp.get("error") == "replicates":
            line += f"; numerical error from {smp.get('passes')} replicates"
        elif smp.get("error") == "pilot":
            pil = smp.get("pilot") or {}
            line += (f"; numerical error measured against the {pil.get('finer_rule')} on "
                     f"{pil.get('grid_pixels')} pilot pixels (every {pil.get('grid_step_px')}th "
                     f"row and column) and {pil.get('local_pixels')} local ones, times "
                     f"{pil.get('safety')}, plus float32 floors")
        line += ")"
        if smp.get("rays_traced") is not None:
            line += f"; {smp['rays_traced']:,} rays traced, pilot included"
        if smp.get("target_error_mrad") is not None:
            line += (f"; target {smp['target_error_mrad']:g} mrad "
                     f"{'met' if smp.get('target_met') else 'NOT met'} at n_rays = "
                     f"{smp.get('n_rays')} (P95 {_num(smp.get('achieved_p95_mrad'), 3)} mrad)")
        lines.append(line)
    lines.append("")
    head = f"{'dir':<4}{'deviation':<20}{'mean':>11}{'RMS':>11}{'P95':>11}{'max':>11}"
    lines.append(head)
    lines.append("-" * len(head))
    for d, s in stats["directions"].items():
        ne = s.get("numerical_error")
        for q, unit in stats["units"].items():
            r = s[q]
            label = q.rsplit("_", 1)[0] + f" ({unit})"
            lines.append(f"{d.upper():<4}{label:<20}" + "".join(
                f"{_num(r[k]):>11}" for k in ("mean", "rms", "p95", "max")))
            if ne and q in ne:  # the rendering's own numerical error of the same statistic
                e = ne[q]
                lines.append(f"{'':<4}{'  ± numerical':<20}{'':>11}" + "".join(
                    f"{_num(e[k], 2):>11}" for k in ("rms", "p95", "max")))
        ex = s.get("coord_vs_exact_px")
        if ex:  # the same coordinate against the exact specular point P
            lines.append(f"{d.upper():<4}{'coord vs exact (px)':<20}" + "".join(
                f"{_num(ex[k]):>11}" for k in ("mean", "rms", "p95", "max")))
            if ne and "coord_px" in ne:  # the decoded coordinate's error (P is exact)
                lines.append(f"{'':<4}{'  ± numerical':<20}{'':>11}" + "".join(
                    f"{_num(ne['coord_px'][k], 2):>11}" for k in ("rms", "p95", "max")))
        p = s["pixels"]
        frac = s["phase_mrad"]["valid_fraction"]
        lines.append(f"    valid {p['valid']} of {p['considered']} considered pixels "
                     f"({100 * frac:.2f} %); masked: low modulation {p['low_modulation']}, "
                     f"decode flags {p['decode_flagged']}, bundle off the monitor "
                     f"{p.get('lobe_off_monitor', 0)}")
        mr = ", ".join(_num(x, 3) for x in s["modulation"]["ratio_median_by_width"])
        lines.append(f"    median modulation ratio by width {stats['widths_px']}: {mr}")
        rq = s["reference_vs_exact_px"]
        lines.append(f"    reference vs exact specular point: RMS {_num(rq['rms'])} px "
                     f"(monitor pixel quantisation of the reference)")
        lines.append("")
    for w in numerical_warnings(stats):
        lines.append("warning: " + w)
    if timings:
        lines.append("timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    return "\n".join(lines).rstrip() + "\n"


#: The deviations the table and ``summary.txt`` print, and the numerical error each has
#: (the coordinate against the exact specular point has the decoded coordinate's).
PRINTED_DEVIATIONS = {"phase_mrad": "phase_mrad", "coord_px": "coord_px", "coord_mm": "coord_mm",
                      "slope_urad": "slope_urad", "coord_vs_exact_px": "coord_px"}


def numerical_warnings(stats: dict, share: float = 0.1) -> list[str]:
    """One warning per direction where the numerical error (RMS or P95) of any deviation
    printed (:data:`PRINTED_DEVIATIONS`) is more than ``share`` of it (issue 18: a number
    whose error is not small is not yet the answer), naming each such number."""
    out = []
    for d, s in stats.get("directions", {}).items():
        ne = s.get("numerical_error") or {}
        over = []
        for q, eq in PRINTED_DEVIATIONS.items():
            for k in ("rms", "p95"):
                v, e = (s.get(q) or {}).get(k), (ne.get(eq) or {}).get(k)
                if (v is not None and e is not None and math.isfinite(v) and math.isfinite(e)
                        and e > share * abs(v)):
                    over.append(f"{q} {k} {v:.3g} ± {e:.2g}")
        if over:
            out.append(f"{d}: the numerical error is more than {100 * share:.0f} % of the "
                       f"deviation ({'; '.join(over)}); raise sampling.n_rays or set "
                       "sampling.target_error_mrad")
    return out


def _fmt(x, spec: str = ".3g") -> str:
    return "nan" if x is None else format(x, spec)



def warning_text(message: str, setting: str, suggested=None) -> str:
    """A diagnostics warning as printed: its message, followed by the setting that fixes
    it (``[setting: sampling.theta_max_deg = 4]``) unless the message names it already."""
    if not setting or setting in message:
        return message
    if suggested is None:
        return f"{message} [setting: {setting}]"
    value = format(suggested, "g") if isinstance(suggested, float) else str(suggested)
    return f"{message} [setting: {setting} = {value}]"



def diagnostics_text(name: str, d: dict) -> str:
    """A short human-readable account of the ``"diagnostics"`` of statistics.json."""
    g = d.get("grid", {})
    lines = [f"pmdsim run diagnostics: {name}",
             f"{d['estimator']} estimator, N = {d['n_rays']}"
             + (f", theta_max {d['theta_max_deg']:g} deg" if "energy" in d else "")
             + f"; {g.get('columns', '?')} x {g.get('rows', '?')} camera-pixel grid", ""]
    e = d.get("energy")
    if e and "fraction_median" in e:
        pc = lambda x: _fmt(None if x is None else 100 * x, ".1f")  # noqa: E731
        lines.append(f"lobe energy inside theta_max: median {pc(e['fraction_median'])} %, "
                     f"min {pc(e['fraction_min'])} %; {100 * e['target']:g} % needs "
                     f"theta_max {_fmt(e['theta_needed_deg_max'], '.2f')} deg (largest over the grid)")
    if "ess_median" in d:
        lines.append(f"effective sample size: median {_fmt(d['ess_median'], '.1f')}, "
                     f"min {_fmt(d['ess_min'], '.1f')} of {d['n_rays']} rays")
    if "phase_se_rad" in d:
        how = {"seeds": "spread over independent rotations of the sample set",
               "pilot": "the render's statement: the rule against a 4 x finer one on a pilot grid",
               "rule": "the stated error of the rule rendered (embedded rules or replicates)",
               }.get(d["phase_se_method"], "N independent rays, an upper bound for the lattice")
        lines.append(f"phase standard error ({d['phase_se_method']} method: {how}), mrad, "
                     "median / P95; fringe modulation:")
        for key, v in d["phase_se_rad"].items():
            direction, width = key.split("/")
            med = None if v["median"] is None else 1e3 * v["median"]
            p95 = None if v["p95"] is None else 1e3 * v["p95"]
            mod = d.get("modulation_median", {}).get(key)
            lines.append(f"  {direction.upper()} {width:>6} px  {_fmt(med):>8} / {_fmt(p95):<8}"
                         f"  modulation {_fmt(mod)}")
    warnings = d.get("warnings", [])
    b = d.get("bounds", {})
    lines.append("")
    if warnings:
        lines += [f"warning: {warning_text(w['message'], w['setting'], w['suggested'])}"
                  for w in warnings]
    else:
        lines.append("no warnings (bounds: energy fraction >= "
                     f"{b.get('min_energy_fraction')}, phase error <= "
                     f"{b.get('max_phase_error_mrad')} mrad, ESS >= "
                     f"{b.get('min_ess_fraction')} N)")
    return "\n".join(lines).rstrip() + "\n"



def summary_text_of(statistics: dict) -> str:
    """summary.txt of one run: the chain's table (when decoded), then the diagnostics."""
    parts = []
    if "directions" in statistics:
        parts.append(summary_text(statistics))
    if "diagnostics" in statistics:
        parts.append(diagnostics_text(statistics.get("name", ""), statistics["diagnostics"]))
    if "reconstruction" in statistics:
        parts.append(reconstruction_text(statistics.get("name", ""), statistics["reconstruction"]))
    return "\n".join(parts)


def value_pm(st: dict, stat: str) -> str:
    """``st[stat]`` as "value ± numerical error" (``st[stat + "_err"]``; the value alone
    where none is stated): the reconstruction's statistics in summary.txt and the figure."""
    e = st.get(stat + "_err")
    if e is None or not math.isfinite(e):
        return f"{st[stat]:.3g}"
    return f"{st[stat]:.3g} ± {e:.2g}"


def excluded_text(rec: dict) -> str:
    """One line: the aperture's nodes that are not reported, by reason, and those the rim
    fit serves (statistics.json's ``excluded_nodes``, ``rim_fit_nodes``)."""
    ex = rec["excluded_nodes"]
    why = {"outside_camera_view": "outside the camera view",
           "pixel_invalid": "on an invalid pixel out of the rim fit's reach",
           "too_few_valid_pixels": "with too few valid pixels around"}
    parts = [f"{ex[k]} {text}" for k, text in why.items() if ex.get(k)]
    head = (f"not reported: {ex['total']} of the aperture's {ex['aperture_nodes']} nodes "
            f"({100 * ex['fraction_of_aperture']:.2g} %)")
    return (head + (": " + ", ".join(parts) if parts else "") +
            f"; {rec.get('rim_fit_nodes', 0)} rim nodes served by the rim fit")


def reconstruction_text(name: str, rec: dict) -> str:
    """The surface-error lines of summary.txt (reconstructed minus true surface)."""
    if "error" in rec:
        return f"reconstruction ({name}): not possible: {rec['error']}\n"
    h, sx, sy = rec["height_error_nm"], rec["slope_error_x_urad"], rec["slope_error_y_urad"]
    lines = [
        f"reconstruction ({name}): {rec['grid_points']} points on a {rec['spacing_mm']:g} mm grid "
        f"({100 * rec['aperture_fraction']:.1f} % of the aperture), {rec['removed']} removed, "
        f"{rec['iterations']} iterations" + ("" if rec["converged"] else " (NOT converged)"),
        f"  height error  RMS {value_pm(h, 'rms')} nm  PV {value_pm(h, 'pv')} nm  P95 {value_pm(h, 'p95')} nm",
        f"  slope error x RMS {value_pm(sx, 'rms_about_zero')} urad  PV {value_pm(sx, 'pv')} urad;  "
        f"y RMS {value_pm(sy, 'rms_about_zero')} urad  PV {value_pm(sy, 'pv')} urad"
        + ("  (value ± the rendering's numerical error)" if "rms_err" in h else ""),
    ]
    if "excluded_nodes" in rec:
        lines.append("  " + excluded_text(rec))
    if rec.get("sphere"):
        sp = rec["sphere"]
        lines.append(f"  best-fit sphere: radius {sp['radius_measured_mm']:.8g} mm reconstructed, "
                     + (f"{sp['radius_true_mm']:.8g} mm true (change {sp['radius_change_mm']:+.3g} mm)"
                        if math.isfinite(sp["radius_true_mm"]) else "the true surface is flat")
                     + f"; curvature change {sp['curvature_change_per_mm'] * 1e3:+.3g} 1/m")
    table = rec.get("zernike_noll_nm") or []
    if table:
        left = [t for t in table if not t["removed"] and t["index"] > 1]
        big = sorted(left, key=lambda t: -abs(t["coefficient"]))[:6]
        lines.append(f"  largest Zernike terms of the height error AFTER removal ({rec.get('removal', '')}; "
                     "Noll, nm RMS each): " + ", ".join(f"Z{t['index']} {t['coefficient']:+.3g}" for t in big))
        gone = [f"Z{t['index']}" for t in table if t["removed"]]
        if gone:
            lines.append(f"  removed terms (about 0 after removal): {', '.join(gone)}")
    else:
        terms = rec.get("terms_nm") or {}
        if terms:
            names = [k for k in terms if k != "basis"]
            big = sorted(names, key=lambda k: -abs(terms[k]))[:6]
            lines.append(f"  largest {terms['basis']} terms of the height error (nm RMS each): "
                         + ", ".join(f"{k} {terms[k]:+.3g}" for k in big))
    if "reference_height_error_nm" in rec:
        r = rec["reference_height_error_nm"]
        lines.append(f"  specular reference (the chain's floor): height RMS {r['rms']:.3g} nm  PV {r['pv']:.3g} nm")
    lines += areal_lines(rec.get("areal") or {})
    return "\n".join(lines) + "\n"


def areal_lines(areal: dict) -> list[str]:
    """summary.txt's lines of the areal parameters and band RMS of each error map
    (``statistics.json`` -> ``reconstruction.areal``)."""
    out = []
    for key, what in (("height_error_nm", "height error"), ("slope_error_x_urad", "slope error x"),
                      ("slope_error_y_urad", "slope error y")):
        st = areal.get(key)
        if not st or st.get("sq") is None:
            continue
        u = st["unit"]
        psd = st.get("psd") or {}
        rms, err = psd.get("band_rms") or {}, psd.get("band_rms_err") or {}
        bands = ", ".join(f"{b} {value_pm({'v': v, 'v_err': err.get(b)}, 'v')}"
                          for b, v in rms.items() if v is not None)
        out.append(f"  ISO 25178, {what}: Sq {value_pm(st, 'sq')} {u}  Sa {value_pm(st, 'sa')} {u}  "
                   f"Sz {value_pm(st, 'sz')} {u}  Ssk {value_pm(st, 'ssk')}  Sku {value_pm(st, 'sku')}  "
                   f"Sdq {value_pm(st, 'sdq')} {st['sdq_unit']}; band RMS {bands} {u} "
                   "(PSD: statistics.json, run.zarr, surface_psd.png)")
    return out



def description(cfg) -> str:
    b = cfg.brdf
    text = f"BRDF {b.model}"
    if b.model != "mirror":
        from ..brdf import equivalent_alphas

        ax, ay = equivalent_alphas(b)
        names = (("tangential", "radial") if cfg.anisotropy.frame == "rotational"
                 else ("x", "y"))
        text += f" alpha_{names[0]} {ax:g}, alpha_{names[1]} {ay:g}"
        var = getattr(b, "variation", None)
        if var is not None:  # spatially varying: the constants hold only where not varied
            varied = [k for k in ("alpha_tangential", "alpha_radial", "rho_s_scale")
                      if getattr(var, k) is not None] if var.radius_mm is not None else None
            text += (f" (varying over the radius {var.radius_mm[0]:g}-{var.radius_mm[-1]:g} mm: "
                     f"{', '.join(varied)})" if varied is not None
                     else f" (varying: map {os.path.basename(var.file)})")
    s = cfg.sampling
    # with a target the pilot picks the order (n_rays is only where it starts): the rule
    # rendered is in the statistics (sampling.nodes) and the dataset (rays_per_pixel)
    n = (f"the rule for a target of {s.target_error_mrad:g} mrad"
         if s.mode == "rule" and s.target_error_mrad is not None else f"N = {s.n_rays}")
    return (text + f"; {s.estimator} estimator, {n}, theta_max {s.theta_max_deg:g} "
            f"deg, {s.mode}; monitor pixel model {cfg.monitor.pixel_model}")
