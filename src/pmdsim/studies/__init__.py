"""Studies over simulations: run diagnostics (:mod:`.diagnostics`) and the convergence
study (:mod:`.convergence`). Nothing here writes files: see :mod:`pmdsim.run`."""
