"""The report of the reproduction: tables, figures, 3D renders and VTU files, assembled into a
self-contained HTML page and a PDF from a stored results folder.

The package only reads stored study results (``runs/*.json``, ``runs/*.npz``, ``tables/*.csv``);
it never runs a solver.  ``python -m reports build --results DIR --out DIR``.
"""
