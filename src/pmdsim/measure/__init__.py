"""Measuring as a PMD system does, on plain arrays (so real camera images work too):
decoding (:mod:`.decode`, files: :mod:`.images`), deviation and statistics
(:mod:`.deviation`), the simulated measurement chain (:mod:`.chain`), monocular
reconstruction of slopes and height (:mod:`.reconstruct`) and slope integration
(:mod:`.integrate`, its solvers :mod:`.poisson`), form removal (:mod:`.form`) and the
propagation of the render's numerical error (:mod:`.numerical`)."""
