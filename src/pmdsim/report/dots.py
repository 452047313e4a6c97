"""Figures of the dot scan: the contact sheet of the reflected dots and their shapes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse

from .scene import _figure, _save, camera_axes, imshow
from .chain_common import _nice, _wrap


# ----------------------------------------------------------------------------- dots
def _grid_layout(table: list[dict]):
    """(n_rows, n_cols, {dot: (row, col)}) arranging the dots like on the monitor (a regular
    grid of their distinct u and v; a near-square grid in dot order when they are scattered)."""
    us = sorted({r["dot_u_px"] for r in table})
    vs = sorted({r["dot_v_px"] for r in table})
    if len(us) * len(vs) == len(table) or len(us) * len(vs) <= 4 * len(table):
        return len(vs), len(us), {r["dot"]: (vs.index(r["dot_v_px"]), us.index(r["dot_u_px"]))
                                  for r in table}
    n = len(table)
    nc = math.ceil(math.sqrt(n))
    return math.ceil(n / nc), nc, {r["dot"]: divmod(k, nc) for k, r in enumerate(table)}


def dot_crop_size(tables: dict, factor: float = 3.0, lo: int = 15, hi: int = 241) -> int:
    """Odd crop size (camera px) that holds +-``factor`` sigma_major of every dot."""
    sig = [r["sigma_major_px"] for t in tables.values() for r in t
           if np.isfinite(r["sigma_major_px"])]
    s = 2 * math.ceil(factor * max(sig, default=5.0)) + 1
    return int(min(max(s, lo), hi)) | 1


def _crop(img: np.ndarray, cc: float, rc: float, size: int) -> np.ndarray:
    h, w = img.shape
    half = size // 2
    out = np.full((size, size), np.nan)
    if not (np.isfinite(cc) and np.isfinite(rc)):
        return out
    c0, r0 = int(round(cc)) - half, int(round(rc)) - half
    rs, cs = slice(max(r0, 0), min(r0 + size, h)), slice(max(c0, 0), min(c0 + size, w))
    out[rs.start - r0:rs.stop - r0, cs.start - c0:cs.stop - c0] = img[rs, cs]
    return out


def plot_dot_contact_sheet(images: dict, tables: dict, path,
                           descriptions: dict | None = None) -> Path:
    """For each variant a grid of crops (same size for all) around each dot's centroid,
    arranged like the dot grid on the monitor; variants side by side.

    Parameters
    ----------
    images : {variant: (n_dots, H, W) ndarray}
        Camera images of the dots.
    tables : {variant: list of dict}
        :func:`pmdsim.measure.chain.dot_table` of each variant.
    """
    descriptions = descriptions or {}
    names = list(images)
    size = dot_crop_size(tables)
    # Rows and columns of dots that no variant sees (off the camera's view of the monitor)
    # are left out of the sheet, and counted in the title.
    seen = {r["dot"] for t in tables.values() for r in t if np.isfinite(r["elongation"])}
    layout_rows = [r for r in tables[names[0]] if r["dot"] in seen] or tables[names[0]]
    nr, nc, where = _grid_layout(layout_rows)
    unseen = len(tables[names[0]]) - len(seen)
    cell = 0.75 if nc * len(names) <= 12 else 0.55
    fig = _figure((len(names) * (nc * cell + 0.9) + 0.3, nr * cell + 1.7))
    subs = fig.subfigures(1, len(names), squeeze=False)[0] if len(names) > 1 else [fig]
    for sub, n in zip(subs, names):
        table = tables[n]
        stack = images[n]  # (n_dots, H, W); may be lazy (xarray): one image read per dot
        peak = max((r["peak"] for r in table if np.isfinite(r["peak"])), default=1.0)
        axes = sub.subplots(nr, nc, squeeze=False, gridspec_kw={"wspace": 0.04, "hspace": 0.04})
        for ax in axes.ravel():
            ax.set_axis_off()
        im = None
        for r in table:
            if r["dot"] not in where:
                continue
            i, j = where[r["dot"]]
            ax = axes[i, j]
            ax.set_axis_on()
            crop = _crop(np.asarray(stack[r["dot"]], np.float64), r["centroid_col"],
                         r["centroid_row"], size)
            im = imshow(ax, crop, cmap="gray", vmin=0, vmax=peak, interpolation="nearest")
            ax.set_xticks([])  # a thumbnail: its size is in the title, its dot's u, v
            ax.set_yticks([])  # at the sheet's edges
            if not np.isfinite(r["elongation"]):
                ax.set_facecolor("0.85")
                ax.text(0.5, 0.5, "not\nseen", ha="center", va="center", fontsize=6,
                        color="0.3", transform=ax.transAxes)
            else:
                ax.text(0.03, 0.97, f"{r['elongation']:.2f}", ha="left", va="top", fontsize=5,
                        color="#ffd92f", transform=ax.transAxes)
            for s in ax.spines.values():
                s.set_color("0.6")
            if i == nr - 1:
                ax.set_xlabel(f"u {r['dot_u_px']:g}", fontsize=6)
            if j == 0:
                ax.set_ylabel(f"v {r['dot_v_px']:g}", fontsize=6)
        title = n
        if descriptions.get(n):
            title += ": " + descriptions[n]
        title = _wrap(title, int(12 * nc))
        sub.suptitle(title, fontsize=8)
        if im is not None:
            sub.colorbar(im, ax=axes.ravel().tolist(), shrink=0.7, pad=0.02).set_label(
                f"camera value (0 .. brightest dot {peak:.3g})", fontsize=7)
    size_px = tables[names[0]][0].get("dot_size_px") if tables[names[0]] else None
    dot = f"{size_px:g} x {size_px:g} monitor px " if size_px else ""
    fig.suptitle(_wrap(f"dot scan: camera images of the reflected {dot}dot, arranged as the "
                       f"dots on the monitor (u right, v down); crops of {size} x {size} camera "
                       "px around each centroid, in camera orientation; yellow: elongation"
                       + (f"; {unseen} dots that the camera does not see are left out"
                          if unseen else ""),
                       int(fig.get_figwidth() * 13)), fontsize=9)
    return _save(fig, path)


def plot_dot_shapes(images: dict, tables: dict, path, centre_px=None,
                    descriptions: dict | None = None) -> Path:
    """Dot size and shape over the camera frame: 2-sigma ellipses (true scale) at each
    centroid, coloured by elongation, over a faint composite of all dot images; a last panel
    shows the major-axis direction relative to the radial direction from the turning centre
    (``centre_px`` = its image (col, row)), which is constant for a rotationally symmetric
    change in shape.
    """
    import matplotlib as mpl

    descriptions = descriptions or {}
    names = list(images)
    first = next(iter(images.values()))
    h, w = first.shape[1:]
    el = [r["elongation"] for t in tables.values() for r in t if np.isfinite(r["elongation"])]
    norm = mpl.colors.Normalize(1.0, max(2.0, _nice(max(el, default=2.0))))
    cmap = mpl.colormaps["plasma"]
    n_panels = len(names) + (centre_px is not None)
    fig = _figure((5.0 * n_panels + 1.0, 5.0 * h / w + 1.6))
    axes = fig.subplots(1, n_panels, squeeze=False)[0]
    for ax, n in zip(axes, names):
        comp = np.zeros((h, w))
        for q in range(images[n].shape[0]):  # one dot at a time (the stack may be lazy)
            img = np.nan_to_num(np.asarray(images[n][q], np.float64), nan=0.0)
            peak = img.max()
            if peak > 0:
                np.maximum(comp, img / peak, out=comp)
        imshow(ax, comp, cmap="gray_r", vmin=0, vmax=1.5, interpolation="nearest")
        for r in tables[n]:
            if not np.isfinite(r["sigma_major_px"]):
                continue
            e = Ellipse((r["centroid_col"], r["centroid_row"]), 4 * r["sigma_major_px"],
                        4 * r["sigma_minor_px"], angle=r["angle_deg"], fill=False,
                        edgecolor=cmap(norm(r["elongation"])), linewidth=1.4)
            ax.add_patch(e)
            ax.plot(r["centroid_col"], r["centroid_row"], "+", color="k", markersize=3)
        if centre_px is not None:
            ax.plot(*centre_px, marker="x", color="#2ca02c", markersize=9, mew=2)
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
        ax.set_aspect("equal")
        camera_axes(ax)
        sm = [r["sigma_major_px"] for r in tables[n] if np.isfinite(r["sigma_major_px"])]
        em = [r["elongation"] for r in tables[n] if np.isfinite(r["elongation"])]
        ax.set_title(f"{n}: 2-sigma ellipses (true scale)\nsigma_major {min(sm):.2g}-"
                     f"{max(sm):.3g} px, elongation {min(em):.2g}-{max(em):.3g}"
                     if sm else f"{n}: no dots seen", fontsize=8)
    sm = mpl.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=list(axes[:len(names)]), shrink=0.8, pad=0.01).set_label(
        "elongation sigma_major / sigma_minor", fontsize=8)
    if centre_px is not None:
        ax = axes[-1]
        markers = ["o", "s", "^", "D"]
        for k, n in enumerate(names):
            az, rel, size, round_ = [], [], [], []
            for r in tables[n]:
                if not np.isfinite(r["sigma_major_px"]):
                    continue
                if r["elongation"] < 1.1:  # orientation undefined for a round dot
                    dx, dy = r["centroid_col"] - centre_px[0], r["centroid_row"] - centre_px[1]
                    round_.append(math.degrees(math.atan2(dy, dx)))
                    continue
                dx, dy = r["centroid_col"] - centre_px[0], r["centroid_row"] - centre_px[1]
                radial = math.degrees(math.atan2(dy, dx))
                diff = (r["angle_deg"] - radial + 90) % 180 - 90
                az.append(radial)
                rel.append(diff)
                size.append(r["elongation"])
            ax.scatter(az, rel, c=size, cmap=cmap, norm=norm, marker=markers[k % 4],
                       edgecolor="k", linewidth=0.4, s=30, label=n)
            if round_:  # drawn on the zero line, hollow: no orientation to speak of
                ax.scatter(round_, np.zeros(len(round_)), marker=markers[k % 4],
                           facecolor="none", edgecolor="0.5", linewidth=0.6, s=30)
        ax.axhline(0, color="0.5", linewidth=0.6)
        ax.set_ylim(-90, 90)
        ax.set_yticks([-90, -45, 0, 45, 90])
        ax.set_xlabel("azimuth of the dot about the turning centre in the image (deg)",
                      fontsize=8)
        ax.set_ylabel("major axis - radial direction (deg)", fontsize=8)
        ax.set_title("orientation of the dot's major axis\n0 = radial, +-90 = tangential "
                     "(colour: elongation; hollow: round, elongation < 1.1)", fontsize=8)
        ax.legend(handles=[Line2D([], [], marker=markers[k % 4], linestyle="", color="0.5",
                                  label=n) for k, n in enumerate(names)], fontsize=7)
        ax.tick_params(labelsize=7)
    fig.suptitle("dot scan: size and elongation per position (second moments above "
                 "5 % of each dot's maximum); x: turning centre", fontsize=9)
    return _save(fig, path)


def dot_figures(folder: Path, images: dict, tables: dict, sim, descriptions: dict) -> list[Path]:
    """The dot contact sheet and the dot shapes figure (``sim`` for the turning centre in
    camera px, drawn when the anisotropy frame is rotational)."""
    centre = None
    an = sim.scene.anisotropy
    if an.kind == "rotational":
        centre = tuple(float(x) for x in sim.scene.camera.project(an.centre))
    return [plot_dot_contact_sheet(images, tables, folder / "dot_contact_sheet.png",
                                              descriptions),
            plot_dot_shapes(images, tables, folder / "dot_shapes.png", centre,
                                       descriptions)]
