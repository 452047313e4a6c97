"""Figures of the measurement chain (decode -> deviation) and of the dot scan.

For a metrologist's report: physical units on every colour bar, the variant and direction
in every title, symmetric colour scales for deviations, and masked pixels drawn in their
own colours with their counts (never hidden):

- :func:`plot_phase`: wrapped phase of every width and the absolute phase, per direction;
- :func:`plot_deviation`: phase (mrad), monitor coordinate (monitor px) and slope (urad)
  deviation maps;
- :func:`plot_histograms`: histograms of those deviations, X and Y;
- :func:`plot_modulation_ratio`: modulation ratio (surface / reference) per width;
- :func:`plot_masks`: which pixels were valid, masked for low modulation, flagged by the
  decoder, or had no valid reference;
- :func:`plot_overview`: one page with the essentials (fringes, modulation ratio,
  coordinate deviation, histogram, statistics);
- :func:`plot_variant_deviation`: the coordinate deviation of several variants on one
  common scale;
- :func:`plot_dot_contact_sheet`, :func:`plot_dot_shapes`: the dot scan;
- :func:`plot_decoded`: maps of a decoded image set (``pmdsim decode``).

All functions draw on Agg :class:`~matplotlib.figure.Figure` objects (no pyplot) and take
in-memory xarray Datasets with the variables of :func:`pmdsim.store.schema.assign_to_dataset`.
"""

from __future__ import annotations

# The figures live in chain_common (shared), chain_maps, overview and dots; every name is
# re-exported here (``from pmdsim.report import chain as plot_chain``).
from .chain_common import (  # noqa: F401
    CLASS_COLOURS, DEVIATIONS, DEV_CMAP, DIR_COLOURS, OVERVIEW_DPI, VS_EXACT, VS_MIRROR,
    coord_vs_exact, symmetric_limit,
)
from .chain_maps import (
    plot_decoded, plot_deviation, plot_histograms, plot_masks, plot_modulation_ratio,
    plot_phase,
)
from .overview import plot_overview, plot_variant_deviation
from .dots import dot_crop_size, dot_figures, plot_dot_contact_sheet, plot_dot_shapes  # noqa: F401
from .scene import DPI


__all__ = ["plot_phase", "plot_deviation", "plot_histograms", "plot_modulation_ratio",
           "plot_masks", "plot_overview", "plot_variant_deviation", "plot_dot_contact_sheet",
           "plot_dot_shapes", "plot_decoded", "dot_figures", "symmetric_limit", "DPI"]
