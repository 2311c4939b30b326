"""The publications' studies: their experiments as study files (:mod:`.reproduce`), the drivers of
what cannot be data (:mod:`.pareto`, :mod:`.stability`, :mod:`.performance`, :mod:`.baudet`,
:mod:`.engines`, :mod:`.modes_study`, :mod:`.regression`), the publications' values
(:mod:`.values`, :mod:`.publications`) and the tables, claims and verdict the report formats
(:mod:`.tables`, :mod:`.claims`, :mod:`.verdict`, :mod:`.equilibria`).

It builds on :mod:`studies.sweep` and :mod:`studies.study`; neither imports it.
"""
