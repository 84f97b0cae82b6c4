"""``hemocircuit reproduce``: every figure and number of thesis chapters 4-6 that the model can
produce, regenerated from the bundled netlists and protocols into one self-contained HTML
report (docs/reproduce.md).

    from hemocircuit.reproduce import build
    report = build("report/", quick=True, only=["ch4_steady"])   # report.index: report/index.html

Layout of the output folder: ``index.html`` (figures embedded, statements table at the top),
``figures/*.png`` (the same figures as files), ``data/*.csv`` (the data behind each figure,
with provenance), ``statements.csv`` (the table) and ``provenance.json``.
"""
from __future__ import annotations

from .build import build  # noqa: F401
