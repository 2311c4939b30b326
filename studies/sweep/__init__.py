"""The machinery of a sweep: scenes × solvers as tasks (:mod:`.runner`), computed in this process,
on a local pool or on Dask (:mod:`.executors`), stored once and resumable (:mod:`.store`), read
back (:mod:`.results`); the estimates that guard and order them (:mod:`.sizing`, :mod:`.roles`,
:mod:`.rest_bound`), the cost of a method (:mod:`.cost`) and the metrics of a run against its
reference (:mod:`.compare`, :mod:`.mode_pairs`, :mod:`.dynamics`, :mod:`.transients`).

Nothing here knows a publication or a command line: :mod:`studies.study` (the study-file format),
:mod:`studies.paper` (the publication's studies) and :mod:`studies.cli` (the ``hybmss`` command)
build on it.
"""
