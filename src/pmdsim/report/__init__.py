"""Figures and text summaries of runs, drawn from a run's dataset (and, for the set-up
figure, the simulation it describes): :mod:`.scene`, :mod:`.chain`, :mod:`.convergence`,
:mod:`.text`."""
