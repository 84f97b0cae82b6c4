"""Result columns as pyarrow arrays: the rows of a CSV table (:func:`rows_text`, pyarrow's C++
CSV writer: 10 001 rows x 36 float columns in tens of milliseconds, where one Python ``repr``
per cell takes ~0.4 s) and the typed columns of a Parquet file (:func:`typed_array`).  Arrays
are built from numpy buffers: ``pa.array`` would import pandas (0.5-0.8 s) to check its
argument's type.

Floats are written as their shortest round-trip decimal (exact: reading a file back gives the
same numbers); only the notation differs from Python's ``repr`` (``2.5e-7`` and ``80``, not
``2.5e-07`` and ``80.0``).  A float column whose every value is an integer is written with
``repr`` (``60.0``), so a reader that types columns by their cells
(:func:`hemocircuit.results._typed`, pandas) keeps it a float column.  Flags are written as
``True``/``False``; text is quoted where CSV needs it (all text cells of a table that has one).
"""
from __future__ import annotations

import io
import os
import re
import stat

import numpy as np

_SPECIAL = re.compile(r'[,"\n\r]')
#: rows below which a table is written in one block (threads cost more than they save)
_BLOCK_ROWS = 1000
#: blocks per core: small enough that the disk takes the first blocks while the last are formatted
_BLOCKS_PER_CORE = 4


def write_rows(fh, columns, cell):
    """Write the table body (no header) of equally long 1-D ``columns`` to the binary file
    ``fh``, one ``\\n``-terminated line per row.  ``cell(v)``: the text of a value that is not a
    number (flags, text, None).

    pyarrow's writer releases the GIL, so blocks of rows are formatted on every core at once
    and written in order as they finish (formatting the floats is most of a long run's write).
    On a real file each written block is handed to the disk (fdatasync, in a background thread)
    while later blocks are formatted, so the caller's closing fsync has little left to wait for:
    10 001 rows x 36 columns 55-61 -> 49-56 ms with the fsync of :func:`hemocircuit.io.atomic_file`
    (docs/performance.md, "Writing results")."""
    if not columns or not len(columns[0]):
        return
    import pyarrow as pa
    import pyarrow.csv as pacsv

    arrays = [_arrow_column(a, cell) for a in columns]
    texts = [t for arr in arrays if pa.types.is_large_string(arr.type) for t in arr.to_pylist()]
    # quote text only where CSV needs it (a delimiter, a quote, a line break, or empty: so a
    # one-column row survives); pyarrow's "needed" style would quote every text cell
    style = "needed" if any(not t or _SPECIAL.search(t) for t in texts) else "none"
    table = pa.Table.from_arrays(arrays, names=[f"c{i}" for i in range(len(columns))])
    n = table.num_rows
    cores = os.cpu_count() or 1
    block = max(_BLOCK_ROWS, -(-n // (_BLOCKS_PER_CORE * cores)))
    options = pacsv.WriteOptions(include_header=False, quoting_style=style, batch_size=block)

    def text(start):
        out = io.BytesIO()
        pacsv.write_csv(table.slice(start, block), out, options)
        return out.getvalue()

    if n <= block:
        fh.write(text(0))
        return
    from concurrent.futures import ThreadPoolExecutor

    fd = _disk_file(fh)
    with ThreadPoolExecutor(max_workers=cores) as pool, ThreadPoolExecutor(max_workers=1) as disk:
        synced = []
        for part in pool.map(text, range(0, n, block)):
            fh.write(part)
            if fd is not None:
                fh.flush()
                synced.append(disk.submit(_datasync, fd))
        for job in synced:
            job.result()


def _disk_file(fh):
    """The descriptor of ``fh`` if it is a regular file (not a buffer or a pipe), else None."""
    try:
        fd = fh.fileno()
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is an OSError
        return None
    return fd if stat.S_ISREG(os.fstat(fd).st_mode) else None


def _datasync(fd):
    """Start the disk on what is written so far (fdatasync where the OS has it)."""
    getattr(os, "fdatasync", os.fsync)(fd)


def rows_text(columns, cell) -> str:
    """The table body of :func:`write_rows` as text."""
    out = io.BytesIO()
    write_rows(out, columns, cell)
    return out.getvalue().decode()


def _arrow_column(a, cell):
    """A column for the CSV writer: numbers as numbers, the rest (and whole-number floats) as text."""
    a = np.asarray(a)
    if a.dtype.kind == "f":
        if not (np.isfinite(a).all() and bool((a == np.trunc(a)).all())):
            return typed_array(a)
        return _text_array([repr(v) for v in a.tolist()])  # 60.0, not 60: read back as a float column
    if a.dtype.kind in "iu":
        return typed_array(a)
    return _text_array([cell(v) for v in a.tolist()])  # flags, text, complex: their text


def typed_array(a):
    """The pyarrow array of a column with its type: float64, int64, bool, or text (None as null)."""
    import pyarrow as pa

    a = np.asarray(a)
    if a.dtype.kind == "f":
        data = np.ascontiguousarray(a, dtype=np.float64)
        return pa.Array.from_buffers(pa.float64(), len(data), [None, pa.py_buffer(data)])
    if a.dtype.kind in "iu":
        data = np.ascontiguousarray(a, dtype=np.int64)
        return pa.Array.from_buffers(pa.int64(), len(data), [None, pa.py_buffer(data)])
    if a.dtype.kind == "b":
        bits = np.packbits(a.astype(bool), bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), len(a), [None, pa.py_buffer(bits)])
    values = a.tolist()
    return _text_array(["" if v is None else str(v) for v in values], [v is not None for v in values])


def _text_array(texts, valid=None):
    import pyarrow as pa

    encoded = [t.encode() for t in texts]
    offsets = np.cumsum([0] + [len(e) for e in encoded], dtype=np.int64)
    mask = None if valid is None or all(valid) else pa.py_buffer(np.packbits(np.asarray(valid), bitorder="little"))
    return pa.Array.from_buffers(pa.large_string(), len(encoded),
                                 [mask, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))])
