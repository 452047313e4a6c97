"""Studies over simulations, returning results and writing nothing (folders: :mod:`pmdsim.run`,
formats: :mod:`pmdsim.store`): run diagnostics (:mod:`.diagnostics`, warnings
:mod:`.diagnostic_warnings`), the convergence study (:mod:`.convergence`), which stage
removed the valid pixels (:mod:`.valid_pixels`, :mod:`.coverage`), a whole configuration's
physics checks (:mod:`.physics_checks`), the rendered and decoded specular reference
(:mod:`.specular_reference`), the error budget (:mod:`.budget`, :mod:`.budget_error`,
:mod:`.height_rows`, :mod:`.calibration`), parameter sweeps (:mod:`.sweep`) and fitting
alphas to images (:mod:`.fit`, :mod:`.fit_stats`, :mod:`.fit_coverage`)."""
