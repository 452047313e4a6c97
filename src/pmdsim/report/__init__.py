"""Figures and text of runs, drawn from a run's dataset alone (and, for the set-up figure,
the simulation its configuration describes); nothing here imports ``run`` or ``store``.

For a metrologist's report: physical units on every colour bar, the variant and direction
in every title, symmetric colour scales for deviations, and masked pixels drawn in their
own colours with their counts (never hidden). ``scene`` (the set-up, fringe and
modulation figures, shared axes and saving), ``chain_common`` (the measurement chain's
colours, labels and statistics boxes), ``chain_maps`` (phase, deviation, histogram,
modulation-ratio, mask and decoded-image maps), ``overview`` (one page with the
essentials; the variants' deviations on one scale), ``dots`` (the dot scan's contact
sheet and shapes), ``reconstruction`` (slope and height error maps), ``convergence``,
``budget``, ``sweep``, ``texture`` (the other commands' figures), ``text`` (summaries).
"""
