"""Figures of a run (matplotlib, Agg canvas, PNG), like the paper's Fig. 3.

- :func:`plot_setup`: the set-up in 3-D (plate, monitor, camera with a small frustum, a few
  vision rays and their principal reflections) with the scattered bundle of one camera
  pixel in red (the paper's pixel (1, 1) = pixel (0, 0) here), and that bundle's footprint
  on the monitor in monitor px;
- :func:`plot_fringe_images`: X and Y fringe images (finest width, shift 0) side by side;
- :func:`plot_modulation`: the fringe modulation ``|sum f exp(i k c)| / f_hit`` per direction
  and width;
- :func:`plot_variant_fringes`: the fringe images of several variants of a comparison.

The functions draw on :class:`matplotlib.figure.Figure` objects with an Agg canvas (no
pyplot, no global backend change). Nothing in pmdsim imports this module at import time.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.ticker import MaxNLocator

from ..quantiles import nanmedian
from ..trace import specular_monitor_coords, trace_pixels, trace_primary

DPI = 130
RED = "#d62728"


def _figure(size) -> Figure:
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _fixed_figure(size) -> Figure:
    """A figure without a layout engine: its axes are placed by :func:`_axes_at` in inches.
    Constrained layout measures every tick label of every axes before drawing, about a
    third of a figure's drawing time; the default figures are laid out by hand instead."""
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def _axes_at(fig: Figure, x: float, y: float, w: float, h: float, **kw):
    """Axes whose box is (x, y, w, h) inches from the figure's lower left corner."""
    fw, fh = fig.get_size_inches()
    return fig.add_axes((x / fw, y / fh, w / fw, h / fh), **kw)


def _save(fig: Figure, path: str | Path, dpi: float | None = None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # zlib level 1: a fraction of the default's encoding time for a few % larger files
    fig.savefig(path, dpi=DPI if dpi is None else dpi, pil_kwargs={"compress_level": 1})
    return path


#: Camera images are drawn with at most this many pixels along their longer side. A panel
#: is under 600 px wide at DPI, so matplotlib would resample a larger image down to the
#: panel with nearest-pixel interpolation anyway: taking every n-th pixel first gives the
#: same picture at a fraction of the drawing time.
MAX_IMAGE_PX = 640


def imshow(ax, image, **kw):
    """``ax.imshow`` of a (H, W) or (H, W, C) image in camera-pixel coordinates, thinned to
    every n-th pixel (the centre one of each n x n block) when larger than
    :data:`MAX_IMAGE_PX`."""
    image = np.asarray(image)
    h, w = image.shape[:2]
    n = -(-max(h, w) // MAX_IMAGE_PX)
    if n <= 1:
        return ax.imshow(image, **kw)
    small = image[n // 2::n, n // 2::n]
    hs, ws = small.shape[:2]
    im = ax.imshow(small, extent=(-0.5, ws * n - 0.5, hs * n - 0.5, -0.5), **kw)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    return im


def camera_axes(ax, fontsize: float = 8) -> None:
    """Label a camera-image map: axes in camera pixels (column right, row down), a few
    whole-pixel ticks with labels (each tick is ~3 ms of drawing)."""
    ax.set_xlabel("camera column (px)", fontsize=fontsize)
    ax.set_ylabel("camera row (px)", fontsize=fontsize)
    ax.tick_params(labelsize=fontsize - 1)
    ax.xaxis.set_major_locator(MaxNLocator(5, integer=True))
    ax.yaxis.set_major_locator(MaxNLocator(4, integer=True))


def _line(ax, a, b, **kw):
    a, b = np.asarray(a), np.asarray(b)
    ax.plot([a[0], b[0]], [a[1], b[1]], [a[2], b[2]], **kw)


def _lines(ax, segments, **kw):
    """3-D line segments [(a, b), ...] as one collection."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    if segments:
        ax.add_collection3d(Line3DCollection(
            [np.array([a, b], float) for a, b in segments], **kw))


def _plane_hit(monitor, origin, dirs):
    """Distance along ``dirs`` (R, 3) from ``origin`` to the monitor *plane* (NaN if behind)."""
    dn = dirs @ monitor.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((monitor.centre - origin) @ monitor.normal) / dn
    return np.where((dn < 0) & (t > 0), t, np.nan)


def _set_equal_box(ax, points, pad_frac=0.04):
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = pad_frac * (hi - lo).max()
    lo, hi = lo - pad, hi + pad
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)  # equal aspect: 1 mm is 1 mm along every axis
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")


def _draw_scene(ax, sim, bundle, vision, pixel, full: bool):
    """Draw plate, monitor, vision rays and the red bundle; with ``full`` also the camera and
    whole vision rays, otherwise vision rays are cut 0.35 x the monitor distance before the
    surface. Returns the points that must be in view."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    scene = sim.scene
    cam, mon, surf = scene.camera, scene.monitor, scene.surface
    h, w = sim.shape
    c = cam.position
    pts = []
    outline = surf.outline()
    ax.add_collection3d(Poly3DCollection([outline[:-1]], facecolor="0.75", alpha=0.45,
                                         edgecolor="0.2", linewidth=1.2))
    pts.append(outline)
    corners_uv = np.array([[-0.5, -0.5], [mon.width - 0.5, -0.5],
                           [mon.width - 0.5, mon.height - 0.5], [-0.5, mon.height - 0.5]])
    mon_corners = mon.pixel_to_world(corners_uv[:, 0], corners_uv[:, 1])
    ax.add_collection3d(Poly3DCollection([mon_corners], facecolor="#9ecae1", alpha=0.45,
                                         edgecolor="#08519c", linewidth=1.2))
    # The monitor's first row (v = 0 edge) drawn thicker: orientation at a glance.
    _line(ax, mon_corners[0], mon_corners[1], color="#08519c", linewidth=2.5)
    pts.append(mon_corners)
    mon_dist = float(np.linalg.norm(mon.centre - surf.outline()[:-1].mean(axis=0)))
    cut = 0.35 * mon_dist

    if full:
        reach = 0.12 * float(np.linalg.norm(surf.outline()[:-1].mean(axis=0) - c))
        corner_px = np.array([[0, 0], [0, w - 1], [h - 1, w - 1], [h - 1, 0]], float)
        corigins, cdirs = cam.chief_rays(corner_px[:, 0], corner_px[:, 1])
        # a telecentric camera's field: parallel rays from its entrance plane's corners
        far = corigins + cdirs * (reach / (cdirs @ cam.rotation[:, 2]))[:, None]
        for o, p in zip(corigins, far):
            _line(ax, o, p, color="k", linewidth=0.8)
        ax.add_collection3d(Poly3DCollection([far], facecolor="0.3", alpha=0.25,
                                             edgecolor="k", linewidth=0.8))
        ax.scatter(*c, color="k", s=18)
        ax.text(*c, "  camera", fontsize=8)
        pts += [far, c[None]]
        ax.text(*mon_corners[2], "  monitor", color="#08519c", fontsize=8)
        ax.text(*outline[1], "  surface", color="0.2", fontsize=8)

    def start(s):
        d = cam.directions_to_camera(s)
        if full:  # the projection centre, or the entrance plane of a telecentric camera
            return c if not cam.telecentric else s + d * ((s - c) @ cam.rotation[:, 2])
        return s + cut * d

    # one collection per kind of ray (a 3-D line per ray costs ~3 ms to create and draw)
    _lines(ax, [(start(s), s) for s, _, _ in vision], color="#2171b5", linewidth=0.6,
           alpha=0.8)
    _lines(ax, [(s, s + t * p_dir) for s, p_dir, t in vision if np.isfinite(t)],
           color="#6baed6", linewidth=0.6, alpha=0.8)

    u, v, dirs, o, hit, plane_t = bundle
    if np.all(np.isfinite(o)):
        _line(ax, start(o), o, color=RED, linewidth=1.3)
        _lines(ax, [(o, e) for e in mon.pixel_to_world(u[hit], v[hit])], color=RED,
               linewidth=0.5, alpha=0.6)
        miss_len = 0.5 * (np.nanmedian(plane_t) if np.isfinite(plane_t).any()
                          else np.linalg.norm(mon.centre - o))
        _lines(ax, [(o, o + miss_len * d) for d in dirs[~hit]], color=RED, linewidth=0.7,
               linestyle="--", alpha=0.9)
        ax.scatter(*o, color=RED, s=12)
    return np.concatenate([np.asarray(p).reshape(-1, 3) for p in pts])


def pixel_on_part(sim, grid: int = 33) -> tuple[int, int]:
    """(row, col) whose bundle the set-up figure draws: (0, 0) (the paper's pixel (1, 1))
    when its vision ray hits the surface, else, of a ``grid`` x ``grid`` lattice of pixels,
    the one on the part nearest the image centre ((0, 0) when none is)."""
    h, w = sim.shape
    if trace_primary(sim.scene, 0, 1).valid[0, 0]:
        return (0, 0)
    best, dist = (0, 0), np.inf
    cols = np.unique(np.linspace(0, w - 1, grid).round().astype(int))
    for r in np.unique(np.linspace(0, h - 1, grid).round().astype(int)):
        ok = trace_primary(sim.scene, int(r), int(r) + 1).valid[0, cols]
        if ok.any():
            d = (r - (h - 1) / 2) ** 2 + (cols[ok] - (w - 1) / 2) ** 2
            k = int(np.argmin(d))
            if d[k] < dist:
                best, dist = (int(r), int(cols[ok][k])), d[k]
    return best


def plot_setup(sim, path: str | Path, pixel: tuple[int, int] | None = None,
               n_vision: int = 3) -> Path:
    """The set-up like the paper's Fig. 3a, with the scattered bundle of camera ``pixel``.

    Three panels: the whole set-up in 3-D (equal aspect, mm); a 3-D close-up of surface
    and monitor; the footprint of the pixel's bundle on the monitor (monitor px, colour =
    BRDF weight). Rays of the bundle that miss the monitor are drawn shorter and dashed
    (3-D) or as crosses where they cross the monitor plane (footprint).

    Parameters
    ----------
    sim : Simulation
    path : path of the PNG to write
    pixel : (row, col), 0-based, optional
        Pixel whose bundle is drawn in red; (0, 0) is the paper's pixel (1, 1). Default
        (:func:`pixel_on_part`): (0, 0) when it sees the surface, else a pixel on the part
        near the image centre.
    n_vision : int
        Vision rays and their principal reflections are drawn for an
        ``n_vision x n_vision`` grid of pixels.
    """
    import importlib

    importlib.import_module("mpl_toolkits.mplot3d")  # registers the 3-D projection

    scene = sim.scene
    mon = scene.monitor
    h, w = sim.shape
    if pixel is None:
        pixel = pixel_on_part(sim)

    vision = []
    rows = np.unique(np.linspace(0, h - 1, n_vision).round().astype(int))
    cols = np.unique(np.linspace(0, w - 1, n_vision).round().astype(int))
    for r in rows:
        hits = trace_primary(scene, int(r), int(r) + 1)
        for col in cols:
            if hits.valid[0, col] and (r, col) != tuple(pixel):
                s, p_dir = hits.point[0, col], hits.principal[0, col]
                vision.append((s, p_dir, _plane_hit(mon, s, p_dir[None])[0]))

    u, v, weight, dirs, origin = sim.transport([pixel[0]], [pixel[1]])
    u, v, f, dirs, o = u[0], v[0], weight[0], dirs[0], origin[0]
    hit = np.isfinite(u)
    valid = bool(np.all(np.isfinite(o)))
    plane_t = _plane_hit(mon, o, dirs) if valid else np.full(len(u), np.nan)
    bundle = (u, v, dirs, o, hit, plane_t)
    one_based = f"({pixel[0] + 1}, {pixel[1] + 1})"
    note = (f"{int(hit.sum())} of {len(u)} rays hit the monitor" if valid
            else "its vision ray misses the surface")

    # laid out by hand (inches): two 3-D views and the footprint with its colour bar
    fig = _fixed_figure((16.0, 6.0))
    ax = _axes_at(fig, 0.0, 0.1, 5.0, 5.4, projection="3d")
    _set_equal_box(ax, _draw_scene(ax, sim, bundle, vision, pixel, full=True))
    ax.view_init(elev=18, azim=-70)
    ax.set_title("PMD set-up (mm, equal aspect)", fontsize=10)

    axz = _axes_at(fig, 4.9, 0.1, 6.3, 5.4, projection="3d")
    _set_equal_box(axz, _draw_scene(axz, sim, bundle, vision, pixel, full=False))
    axz.view_init(elev=18, azim=-70)
    axz.set_title(f"surface and monitor; red: scattered bundle of camera pixel {one_based} "
                  f"(1-based)\n{note}; dashed: rays that miss", fontsize=10)
    for a, ny in ((ax, 2), (axz, 4)):  # the full view is thin along y: fewer ticks
        a.xaxis.set_major_locator(MaxNLocator(4))
        a.yaxis.set_major_locator(MaxNLocator(ny))
        a.zaxis.set_major_locator(MaxNLocator(4))

    ax2 = _axes_at(fig, 11.95, 0.75, 3.0, 4.6)
    if valid:
        cu, cv = u.copy(), v.copy()
        if (~hit).any():  # where the missing rays cross the monitor plane
            q = o + plane_t[~hit][:, None] * dirs[~hit]
            uv = mon.world_to_pixel(q)
            cu[~hit], cv[~hit] = uv[:, 0], uv[:, 1]
        sc = ax2.scatter(cu[hit], cv[hit], c=f[hit], cmap="Reds", s=22, edgecolor="k",
                         linewidth=0.3)
        fig.colorbar(sc, cax=_axes_at(fig, 15.15, 1.0, 0.15, 4.1), label="BRDF weight f (1/sr)")
        if (~hit).any():
            ax2.scatter(cu[~hit], cv[~hit], marker="x", color="0.4", s=22,
                        label="misses the monitor")
        # P, the specular direction, where it meets the monitor (a Gauss rule's or the
        # radiometric estimator's rays do not include it: ray 0 is P only in the paper's sets)
        pu, pv, p_hit = specular_monitor_coords(scene, trace_pixels(scene, [pixel[0]], [pixel[1]]))
        if p_hit[0, 0]:
            ax2.scatter([pu[0, 0]], [pv[0, 0]], marker="+", color="k", s=120,
                        label="P (specular direction)")
        ax2.add_patch(Rectangle((-0.5, -0.5), mon.width, mon.height, fill=False,
                                edgecolor="#08519c", linewidth=1.5, label="monitor edge"))
        fu, fv = cu[np.isfinite(cu)], cv[np.isfinite(cv)]
        m = 8
        ax2.set_xlim(fu.min() - m, fu.max() + m)
        ax2.set_ylim(fv.max() + m, fv.min() - m)  # rows grow downwards
        ax2.set_aspect("equal")
        ax2.legend(loc="lower right", fontsize=7)
    ax2.set_xlabel("u (monitor px)")
    ax2.set_ylabel("v (monitor px)")
    ax2.set_title(f"bundle of camera pixel {one_based} on the monitor", fontsize=10)
    return _save(fig, path)


def _modulation(ds, direction, width) -> np.ndarray:
    """|sums| / f_hit, or B/A decoded from the shifted images when no sums are stored."""
    if "fringe_sums_real" in ds:
        re = ds["fringe_sums_real"].sel(direction=direction, width=width).values
        im = ds["fringe_sums_imag"].sel(direction=direction, width=width).values
        fh = ds["f_hit"].values
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.hypot(re, im) / fh
    stack = ds["fringes"].sel(direction=direction, width=width).values.astype(np.float64)
    deltas = ds["shift"].values
    z = np.tensordot(np.exp(-1j * deltas), stack, axes=(0, 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return 2 * np.abs(z) / stack.sum(axis=0)


def plot_fringe_images(ds, path: str | Path, width: float | None = None, shift: int = 0) -> Path:
    """X and Y fringe images of one width (default: the finest) side by side, like the
    paper's Fig. 3b/c, on one grey scale with a colour bar."""
    widths = ds["width"].values
    width = float(widths.min()) if width is None else float(width)
    dirs = [str(d) for d in ds["direction"].values]
    imgs = [ds["fringes"].sel(direction=d, width=width).isel(shift=shift).values for d in dirs]
    finite = [i[np.isfinite(i)] for i in imgs]
    vmax = max((float(f.max()) for f in finite if f.size), default=1.0)
    h, w = imgs[0].shape
    fig = _figure((5.2 * len(dirs) + 1.2, 5.2 * h / w + 0.9))
    axes = fig.subplots(1, len(dirs), squeeze=False)[0]
    delta = float(ds["shift"].values[shift])
    im = None
    for ax, d, img in zip(axes, dirs, imgs):
        im = imshow(ax, img, cmap="gray", vmin=0.0, vmax=vmax, interpolation="nearest")
        mod = nanmedian(_modulation(ds, d, width))
        ax.set_title(f"{d.upper()} fringes, width {width:g} monitor px, shift {delta:.2f} rad\n"
                     f"median modulation {mod:.2f}", fontsize=10)
        camera_axes(ax, 10)
    est = ds.attrs.get("estimator", "paper")
    fig.colorbar(im, ax=list(axes), shrink=0.85,
                 label="camera value (" + ("(1/N) sum f L" if est == "paper" else
                                           "sum f L / sum f") + ")")
    return _save(fig, path)


def plot_modulation(ds, path: str | Path) -> Path:
    """Modulation maps (|sums| / f_hit) for every direction (rows) and width (columns)."""
    widths = [float(x) for x in ds["width"].values]
    dirs = [str(d) for d in ds["direction"].values]
    h, w = ds["f_hit"].shape
    fig = _figure((3.9 * len(widths) + 1.0, (3.9 * h / w + 0.6) * len(dirs)))
    axes = fig.subplots(len(dirs), len(widths), squeeze=False)
    im = None
    for i, d in enumerate(dirs):
        for j, wd in enumerate(widths):
            mod = _modulation(ds, d, wd)
            ax = axes[i, j]
            im = imshow(ax, mod, cmap="viridis", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_title(f"{d.upper()}, width {wd:g} px: median {nanmedian(mod):.3f}",
                         fontsize=9)
            camera_axes(ax)
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="modulation B/A")
    return _save(fig, path)


def plot_variant_fringes(datasets: dict, path: str | Path, descriptions: dict | None = None,
                         shift: int = 0) -> Path:
    """Fringe images of several variants (rows) in X and Y (columns) at the finest width.

    Each row has its own grey scale (absolute levels of different BRDFs can differ by
    orders of magnitude under the paper's estimator); titles give the median modulation.
    """
    descriptions = descriptions or {}
    names = list(datasets)
    first = datasets[names[0]]
    dirs = [str(d) for d in first["direction"].values]
    width = float(first["width"].values.min())
    h, w = first["f_hit"].shape
    fig = _figure((5.0 * len(dirs) + 1.4, (5.0 * h / w + 0.8) * len(names)))
    axes = fig.subplots(len(names), len(dirs), squeeze=False)
    for i, name in enumerate(names):
        ds = datasets[name]
        imgs = [ds["fringes"].sel(direction=d, width=width).isel(shift=shift).values
                for d in dirs]
        vmax = max((float(np.nanmax(x)) for x in imgs if np.isfinite(x).any()), default=1.0)
        im = None
        for j, (d, img) in enumerate(zip(dirs, imgs)):
            ax = axes[i, j]
            im = imshow(ax, img, cmap="gray", vmin=0.0, vmax=vmax, interpolation="nearest")
            mod = nanmedian(_modulation(ds, d, width))
            ax.set_title(f"{name}: {d.upper()} fringes, width {width:g} px\n"
                         f"median modulation {mod:.2f}", fontsize=9)
            camera_axes(ax)
        if descriptions.get(name):
            axes[i, 0].set_ylabel(textwrap.fill(descriptions[name], 40), fontsize=8)
        fig.colorbar(im, ax=list(axes[i]), shrink=0.85, label="camera value")
    return _save(fig, path)


__all__ = ["plot_setup", "plot_fringe_images", "plot_modulation", "plot_variant_fringes"]
