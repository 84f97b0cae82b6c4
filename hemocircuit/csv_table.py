"""The rows of a CSV table, written by pyarrow's CSV writer (C++): 10 001 rows x 36 float
columns in tens of milliseconds, where one Python ``repr`` per cell takes ~0.4 s.

Floats are written as their shortest round-trip decimal (exact: reading a file back gives the
same numbers); only the notation differs from Python's ``repr`` (``2.5e-7`` and ``80``, not
``2.5e-07`` and ``80.0``).  A float column whose every value is an integer is written with
``repr`` (``60.0``), so a reader that types columns by their cells
(:func:`hemocircuit.results._typed`, pandas) keeps it a float column.  Flags are written as
``True``/``False``; text is quoted where CSV needs it (all text cells of a table that has one).
"""
from __future__ import annotations

import io
import re

import numpy as np

_SPECIAL = re.compile(r'[,"\n\r]')


def rows_text(columns, cell) -> str:
    """The table body (no header) of equally long 1-D ``columns``, one ``\\n``-terminated line
    per row.  ``cell(v)``: the text of a value that is not a number (flags, text, None)."""
    if not columns or not len(columns[0]):
        return ""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    arrays = [_arrow_column(a, cell) for a in columns]
    texts = [t for arr in arrays if isinstance(arr, list) for t in arr]
    # quote text only where CSV needs it (a delimiter, a quote, a line break, or empty: so a
    # one-column row survives); pyarrow's "needed" style would quote every text cell
    style = "needed" if any(not t or _SPECIAL.search(t) for t in texts) else "none"
    table = pa.table(arrays, names=[f"c{i}" for i in range(len(columns))])
    out = io.BytesIO()
    pacsv.write_csv(table, out, pacsv.WriteOptions(include_header=False, quoting_style=style,
                                                      batch_size=max(1024, len(columns[0]))))
    return out.getvalue().decode()


def _arrow_column(a, cell):
    a = np.asarray(a)
    if a.dtype.kind == "f":
        whole = np.isfinite(a).all() and bool((a == np.trunc(a)).all())
        return [repr(v) for v in a.tolist()] if whole else a.astype(np.float64, copy=False)
    if a.dtype.kind in "iu":
        return a.astype(np.int64, copy=False)
    return [cell(v) for v in a.tolist()]  # flags, text, complex: their text, quoted by the writer
