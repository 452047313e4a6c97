"""Measuring as a PMD system does, on plain arrays (so real camera images work too):
decoding (:mod:`.decode`, files: :mod:`.images`), deviation and statistics
(:mod:`.deviation`) and the simulated measurement chain (:mod:`.chain`)."""
