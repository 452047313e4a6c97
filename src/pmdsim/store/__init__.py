"""The run folder's format: what a run writes and how it is read back.

``schema`` (the run dataset's variables and ``load_run``, the one way to open a run),
``writer`` (the Zarr encoding and the writer, whole or in parts behind a run),
``lazy_arrays`` (the dataset's lazily read variables), ``folder`` (atomic output folders),
``folder_lock`` (the lock on an output folder, stale temporaries, interrupts),
``manifest`` (``pmdsim-run.json``), ``integrity`` (is a folder whole), ``images``
(integer camera images on disk), ``tables`` (JSON and CSV files), ``export`` (surface maps
for surface-metrology software). Nothing here renders or measures: ``run/`` does, and
hands its arrays to this package.
"""
