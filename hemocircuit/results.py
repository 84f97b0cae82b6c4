"""Results: the one shape every analysis returns.

A :class:`Result` is a table of named columns, each with a unit, plus metadata:

* ``data``      {name: 1-D array}, every column the same length (one row per time point,
                sweep value, frequency or grid member); numbers, yes/no flags or text.
* ``units``     {name: unit}: ``'mmHg'``, ``'mL/s'``, ``'1'`` for a dimensionless number,
                ``''`` for text and yes/no columns (they have no unit).
* ``index``     the names of the independent-variable columns (``['time']``,
                ``['Pa.value']``, ``['art.tau_Ca', 'frequency']``; empty for a point result).
* ``metadata``  ``analysis`` (name), ``status`` (``'complete'`` or ``'partial'``),
                ``settings`` (the analysis's settings and tolerances), ``measures``
                (scalar findings), ``provenance`` (:mod:`hemocircuit.provenance`), and
                per analysis e.g. ``solver`` statistics, ``failed`` members, ``events``.

Files: :meth:`Result.to_csv` writes ``# key: value`` header lines (the metadata, values in
JSON; ``pandas.read_csv(path, comment="#")`` and other readers that skip comments skip them)
and then the table, one value per cell, units only in the header (``name [unit]``).
:meth:`Result.to_json` writes ``{"metadata", "index", "values": {"name [unit]": value}}``
(for a point result a value is a number, otherwise a list).  :meth:`Result.load` reads either
back (columns, units, index and metadata).  Writing is atomic (:func:`hemocircuit.io.atomic_write`).

Dict-like access (``res["Q(Rla)"]``, ``"P(a)" in res``, ``res.keys()``) gives whole columns.
"""
from __future__ import annotations

import csv
import html
import io as _io
import json
import math
import os
import re

import numpy as np


_LABEL = re.compile(r"^(.*) \[([^\[\]]*)\]$")
_INT = re.compile(r"^[-+]?\d+$")


def label(name, unit):
    """'name [unit]' (the column header); text and flag columns (unit '') keep their name."""
    return f"{name} [{unit}]" if unit else name


def parse_label(text):
    """'name [unit]' -> (name, unit); 'name' -> (name, '')."""
    m = _LABEL.match(text.strip())
    return (m.group(1), m.group(2)) if m else (text.strip(), "")


def _column(values):
    a = np.asarray(values)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise ValueError(f"a result column is one-dimensional, got shape {a.shape}")
    return a


def _is_numeric(a):
    return a.dtype.kind in "iuf"


def _unit_of(name, unit, a):
    if not _is_numeric(a):
        return ""  # text and yes/no columns have no unit
    unit = "" if unit is None else str(unit).strip()
    return "1" if unit in ("", "dimensionless") else unit


def jsonable(v):
    """Metadata value -> plain JSON types (numpy scalars and arrays, complex, tuples)."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):  # numbers and flags as they are: one C-level tolist, not a call per value
        return v.tolist() if v.dtype.kind in "iufb" else [jsonable(x) for x in v.tolist()]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, (complex, np.complexfloating)):
        return {"re": float(v.real), "im": float(v.imag)}
    if v is None or isinstance(v, str):
        return v
    return str(v)


def _cell(v):
    if isinstance(v, (bool, np.bool_)):
        return "True" if v else "False"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return "nan" if math.isnan(f) else repr(f)
    return "" if v is None else str(v)


#: result file formats by extension (Result.save, Result.load, --out)
FORMATS = {".csv": "csv", ".txt": "csv", ".json": "json", ".npz": "npz", ".parquet": "parquet"}


def file_format(path, what="--out"):
    """The result format of ``path``'s extension, or a clear error listing them."""
    from .errors import HemocircuitError
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in FORMATS:
        raise HemocircuitError(f"{what} {path}: unknown result format {ext or '(no extension)'!r}; use "
                               f"{', '.join(FORMATS)} (.npz and .parquet are binary and exact, for long runs)")
    return FORMATS[ext]


def _pyarrow():
    from .errors import HemocircuitError
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise HemocircuitError("Parquet files need pyarrow: pip install pyarrow (or write .npz, numpy's binary "
                               "format, or .csv)") from None
    return pa, pq


def _csv_quote(text):
    """Quoted as the csv module quotes (and "" for an empty cell, so a one-column row survives)."""
    return '"' + text.replace('"', '""') + '"' if not text or any(c in text for c in ',"\n\r') else text


def _fmt(v, width=0):
    if isinstance(v, (bool, np.bool_)):
        s = "yes" if v else "no"
    elif isinstance(v, (int, np.integer)):
        s = str(int(v))
    elif isinstance(v, (float, np.floating)):
        s = f"{float(v):.6g}"
    else:
        s = str(v)
    return f"{s:>{width}}" if width else s


class Result:
    """Named columns with units, an independent variable, metadata; see the module docstring.

    Construct with ``Result(columns, units, index=(), metadata=None)``: ``columns`` a mapping
    name -> 1-D array (index columns first is customary; the order is kept), ``units`` a
    mapping name -> unit (missing or 'dimensionless' numeric columns get '1').
    """

    def __init__(self, columns, units=None, index=(), metadata=None):
        units = units or {}
        self.data = {str(k): _column(v) for k, v in columns.items()}
        lengths = {len(v) for v in self.data.values()}
        if len(lengths) > 1:
            raise ValueError(f"result columns differ in length: { {k: len(v) for k, v in self.data.items()} }")
        self.units = {k: _unit_of(k, units.get(k), v) for k, v in self.data.items()}
        self.index = [index] if isinstance(index, str) else list(index)
        missing = [k for k in self.index if k not in self.data]
        if missing:
            raise ValueError(f"index column(s) {missing} are not columns")
        self.metadata = dict(metadata or {})
        self.metadata.setdefault("status", "complete")

    # ------------------------------------------------------------------ dict-like ---------
    def __getitem__(self, key):
        try:
            return self.data[key]
        except KeyError:
            import difflib
            close = difflib.get_close_matches(str(key), list(self.data), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; columns: {', '.join(list(self.data)[:12])}"
            raise KeyError(f"no column {key!r}{hint}") from None

    def __contains__(self, key):
        return key in self.data

    def __iter__(self):
        return iter(self.data)

    def __len__(self):  # as for a dict: the number of columns
        return len(self.data)

    def keys(self):
        return self.data.keys()

    def items(self):
        return self.data.items()

    def get(self, key, default=None):
        return self.data.get(key, default)

    @property
    def columns(self):
        """The dependent columns {name: array} (everything but the index)."""
        return {k: v for k, v in self.data.items() if k not in self.index}

    @property
    def n_rows(self):
        return len(next(iter(self.data.values()))) if self.data else 0

    @property
    def analysis(self):
        return self.metadata.get("analysis", "")

    @property
    def status(self):
        return self.metadata.get("status", "complete")

    @property
    def partial(self):
        return self.status == "partial"

    def check_columns(self, names, what="column"):
        """Raise a clear error (with close matches) for names that are not columns."""
        import difflib
        from .errors import HemocircuitError
        for n in names:
            if n not in self.data:
                close = difflib.get_close_matches(str(n), list(self.data), n=3)
                hint = f"did you mean {', '.join(close)}?" if close else f"columns: {', '.join(list(self.data)[:20])}"
                raise HemocircuitError(f"no {what} {n!r} in the {self.analysis or ''} result; {hint}")

    def label(self, name):
        """The column's header, 'name [unit]'."""
        return label(name, self.units.get(name, ""))

    def rows(self):
        """The table as a list of {name: value} dicts (Python scalars), one per row."""
        names = list(self.data)
        cols = [self.data[n].tolist() for n in names]
        return [dict(zip(names, vals)) for vals in zip(*cols)]

    # ------------------------------------------------------------------ files -------------
    def save(self, path):
        """Write ``path`` in the format its extension names (:data:`FORMATS`: ``.csv``, ``.json``,
        and for long runs the binary ``.npz`` or ``.parquet``); returns it."""
        return getattr(self, "to_" + file_format(path))(path)

    def _file_metadata(self):
        """The metadata as JSON types, file hashes added, in a reading order (what, how, whence)."""
        from .provenance import complete
        md = jsonable(self.metadata)
        complete(md)
        first = [k for k in ("analysis", "status", "error", "settings", "measures", "solver") if k in md]
        last = [k for k in ("provenance",) if k in md]
        return {k: md[k] for k in first + [k for k in md if k not in first + last] + last}

    def to_csv(self, path):
        """Metadata as ``# key: value`` lines, then the table (header ``name [unit]``).  Atomic."""
        from .arrow_tables import write_rows
        from .errors import HemocircuitError
        from .io import atomic_file
        md = self._file_metadata()
        buf = _io.StringIO()
        buf.write(f"# index: {json.dumps(self.index)}\n")
        for key, value in md.items():
            if isinstance(value, dict) and value:
                for sub, v in value.items():  # one line per entry: readable, and grep-able
                    buf.write(f"# {key}.{sub}: {_json_line(v)}\n")
            else:
                buf.write(f"# {key}: {_json_line(value)}\n")
        names = list(self.data)
        buf.write(",".join(_csv_quote(self.label(n)) for n in names) + "\n")
        try:
            with atomic_file(path, "wb") as fh:
                fh.write(buf.getvalue().encode())
                write_rows(fh, [self.data[n] for n in names], _cell)
        except OSError as exc:
            raise HemocircuitError(f"cannot write {path}: {exc.strerror or exc}") from None
        return str(path)

    def to_npz(self, path):
        """numpy's ``.npz`` (binary, exact, compact for long runs): one array per column under its
        header ``name [unit]``, plus ``__index__`` and ``__metadata__`` (JSON text).  Atomic;
        read back by :meth:`load` (no pickles: text columns are stored as unicode arrays)."""
        from .io import atomic_file
        arrays = {self.label(n): (v if _is_numeric(v) or v.dtype.kind == "b" else
                                  np.array([_cell(x) for x in v.tolist()], dtype=str))
                  for n, v in self.data.items()}
        arrays["__index__"] = np.array(json.dumps(self.index))
        arrays["__metadata__"] = np.array(json.dumps(self._file_metadata(), allow_nan=True))
        with atomic_file(path, "wb") as fh:
            np.savez(fh, **arrays)
        return str(path)

    def to_parquet(self, path):
        """Apache Parquet through pyarrow: one column per result column under its header, the
        index and metadata as JSON in the file's key-value metadata."""
        from .arrow_tables import typed_array
        from .io import atomic_file
        pa, pq = _pyarrow()
        table = pa.Table.from_arrays([typed_array(v) for v in self.data.values()],
                                     names=[self.label(n) for n in self.data])
        table = table.replace_schema_metadata({"hemocircuit.index": json.dumps(self.index),
                                               "hemocircuit.metadata": json.dumps(self._file_metadata())})
        with atomic_file(path, "wb") as fh:
            pq.write_table(table, fh)
        return str(path)

    def to_json(self, path):
        """``{"metadata", "index", "values": {"name [unit]": value or list}}``.  Atomic."""
        from .io import atomic_write
        single = self.n_rows == 1
        values = {self.label(n): (jsonable(v.tolist()[0]) if single else jsonable(v)) for n, v in self.data.items()}
        # the metadata indented; each column on one line (json's C encoder: indenting every value
        # of a long run would take the Python encoder and a line per number)
        columns = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in values.items())
        atomic_write(path, '{\n "metadata": ' + json.dumps(self._file_metadata(), indent=1).replace("\n", "\n ")
                     + ',\n "index": ' + json.dumps(self.index) + ',\n "values": {\n' + columns + "\n }\n}\n")
        return str(path)

    @classmethod
    def load(cls, path):
        """A result written by :meth:`to_csv` or :meth:`to_json` (or by any ``hemocircuit``
        command): columns, units, index and metadata as they were saved."""
        from .errors import HemocircuitError, excerpt
        from .inputs import parse_json, read_text

        fmt = file_format(path, "result file")
        try:
            if fmt in ("npz", "parquet"):
                from .inputs import read_bytes
                data = read_bytes(path, "result file", size_limit="RESULT_MB")  # the input policy (inputs.py)
                res = cls._from_npz(data) if fmt == "npz" else cls._from_parquet(data)
            else:
                text = read_text(path, "result file", size_limit="RESULT_MB")
                res = cls._from_json(parse_json(text, str(path), allow_nan=True)) if fmt == "json" else \
                    cls._from_csv(text)
        except (ValueError, KeyError, TypeError, IndexError, AttributeError, OSError) as exc:
            raise HemocircuitError(f"{path}: not a hemocircuit result file ({excerpt(exc, 120)})") from None
        for section in _MAPPING_SECTIONS:
            if not isinstance(res.metadata.get(section, {}), dict):
                raise HemocircuitError(f"{path}: not a hemocircuit result file (its '{section}' metadata is "
                                       f"{excerpt(res.metadata[section], 60)}, not a mapping)")
        return res

    @classmethod
    def _from_npz(cls, data):
        with np.load(_io.BytesIO(data), allow_pickle=False) as z:
            index, meta = json.loads(str(z["__index__"])), json.loads(str(z["__metadata__"]))
            cols, units = {}, {}
            for head in z.files:
                if head.startswith("__"):
                    continue
                name, unit = parse_label(head)
                v = z[head]
                cols[name] = v if v.dtype.kind in "iufb" else np.array(v.tolist(), dtype=object)
                units[name] = unit
        return cls._make(cols, units, index, meta)

    @classmethod
    def _from_parquet(cls, data):
        pa, pq = _pyarrow()
        table = pq.read_table(pa.BufferReader(data))
        md = table.schema.metadata or {}
        cols, units = {}, {}
        for head in table.column_names:
            name, unit = parse_label(head)
            v = table.column(head).to_numpy(zero_copy_only=False)
            cols[name] = v if v.dtype.kind in "iufb" else np.array(v.tolist(), dtype=object)
            units[name] = unit
        return cls._make(cols, units, json.loads(md.get(b"hemocircuit.index", b"[]")),
                         json.loads(md.get(b"hemocircuit.metadata", b"{}")))

    @classmethod
    def _from_json(cls, doc):
        cols, units = {}, {}
        for head, v in doc["values"].items():
            name, unit = parse_label(head)
            cols[name] = _typed([_cell(x) for x in (v if isinstance(v, list) else [v])])
            units[name] = unit
        return cls._make(cols, units, doc.get("index", []), doc.get("metadata", {}))

    @classmethod
    def _from_csv(cls, text):
        lines = text.splitlines()
        meta, index, body = {}, [], []
        for ln in lines:
            if ln.startswith("#"):
                key, sep, value = ln[1:].strip().partition(":")
                if not sep:
                    continue
                value = _parse_json_line(value.strip())
                key = key.strip()
                if key == "index":
                    index = value
                elif "." in key:
                    section, _, sub = key.partition(".")
                    meta.setdefault(section, {})[sub] = value
                else:
                    meta[key] = value
            else:
                body.append(ln)
        rows = list(csv.reader(body))
        if not rows:
            raise ValueError("no table")
        names, units = [], {}
        for head in rows[0]:
            n, u = parse_label(head)
            if n in units:
                raise ValueError(f"column {n!r} appears twice in the header")
            names.append(n)
            units[n] = u
        for i, row in enumerate(rows[1:]):
            if len(row) != len(names):  # zip would drop the columns past a short row
                raise ValueError(f"data row {i + 1} has {len(row)} cells, the header {len(names)}")
        cells = list(zip(*rows[1:])) if len(rows) > 1 else [()] * len(names)
        cols = {n: _typed(list(c)) for n, c in zip(names, cells)}
        return cls._make(cols, units, index, meta)

    @classmethod
    def _make(cls, cols, units, index, meta):
        r = Result.__new__(Result)
        Result.__init__(r, cols, units, index=index, metadata=meta)
        for n, u in units.items():  # keep the file's units exactly (a '' numeric column stays '')
            if n in r.units and u:
                r.units[n] = u
        return r

    # ------------------------------------------------------------------ pandas, notebooks --
    def to_dataframe(self):
        """A pandas DataFrame with the file's headers (``name [unit]``); ``df.attrs`` holds
        ``units``, ``index`` and ``metadata``.  pandas is an optional dependency."""
        try:
            import pandas as pd
        except ImportError:
            from .errors import HemocircuitError
            raise HemocircuitError("to_dataframe() needs pandas, an optional dependency: "
                                   "pip install pandas (or pip install 'hemocircuit[pandas]')") from None
        df = pd.DataFrame({self.label(n): v for n, v in self.data.items()})
        df.attrs.update(units=dict(self.units), index=list(self.index), metadata=jsonable(self.metadata))
        return df

    def _repr_html_(self, max_cols=8, max_rows=10):
        names, rows, col_note, row_note = self._window(max_cols, max_rows)
        head = "".join(f"<th>{html.escape(self.label(n))}</th>" for n in names)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(v))}</td>" for v in r) + "</tr>" if r is not None
                       else f"<tr><td colspan='{len(names)}'>&hellip;</td></tr>" for r in rows)
        notes = "; ".join(x for x in (f"{self.analysis or 'result'} ({self.status})", row_note, col_note) if x)
        return (f"<table><caption style='text-align:left'>{html.escape(notes)}</caption>"
                f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")

    def _window(self, max_cols, max_rows, show=None):
        """(column names, rows (None = the elided middle), column note, row note)."""
        all_names = list(self.data)
        if show:
            self.check_columns(show)
            names = [n for n in self.index if n not in show] + list(show)
        else:
            names = all_names[:max_cols] if max_cols else all_names
        n = self.n_rows
        if max_rows and n > max_rows:
            k = max_rows // 2
            picks = list(range(k)) + [None] + list(range(n - (max_rows - k), n))
        else:
            picks = list(range(n))
        rows = [None if i is None else [self.data[c][i] for c in names] for i in picks]
        col_note = f"showing {len(names)} of {len(all_names)} columns" if len(names) < len(all_names) else ""
        row_note = f"showing {len(picks) - 1} of {n} rows" if None in picks else ""
        return names, rows, col_note, row_note

    def summary(self, max_cols=6, max_rows=12, show=None, where=None):
        """A printable table, and a last line saying what it leaves out ("showing 5 of 37
        columns; all in dc.csv").  ``show``: columns to print (the index is always shown);
        ``where``: the file holding everything (default: 'save()' / '--out' is suggested).
        A one-row result (an operating point) is listed vertically, every column."""
        if self.n_rows == 1 and not show:
            names = list(self.data)
            width = max(len(self.label(k)) for k in names)
            lines = [f"{self.label(k):<{width}}  {_fmt(self.data[k][0])}" for k in names]
            return "\n".join(lines)
        names, rows, col_note, row_note = self._window(max_cols, max_rows, show)
        width = max([14] + [min(len(self.label(n)), 24) for n in names])
        lines = ["  ".join(f"{self.label(n):>{width}}" for n in names)]
        for r in rows:
            lines.append("  ".join(f"{'...':>{width}}" for _ in names) if r is None
                         else "  ".join(_fmt(v, width) for v in r))
        note = "; ".join(x for x in (col_note, row_note) if x)
        if note:
            lines.append(f"({note}; " + (f"all in {where})" if where else
                                          "write them all with --out FILE.csv or Result.save())"))
        return "\n".join(lines)

    # ------------------------------------------------------------------ plots --------------
    def plot(self, path, select=None, title=None):
        """Draw the result to ``path`` (PNG) with its analysis's default plot (the analysis
        module's ``plot_result(result, path, select, title)``), else the series plot of
        :func:`hemocircuit.plotting.plot_series` (outputs of interest, one panel per unit)."""
        import importlib
        module = _PLOTTERS.get(self.analysis)
        if module:
            fn = getattr(importlib.import_module(module), "plot_result", None)
            if fn is not None:
                return fn(self, path, select=select, title=title)
        from .plotting import plot_series
        return plot_series(self, path, select=select, title=title)

    def figure_title(self):
        """'NETLIST.yaml: analysis', the default title of its figures."""
        prov = self.metadata.get("provenance", {}) or {}
        net = prov.get("netlist")
        return f"{os.path.basename(net) if net else ''}: {self.analysis}".strip(": ")

    def __repr__(self):
        return (f"<{type(self).__name__} {self.analysis or ''} {self.status}: {self.n_rows} rows x "
                f"{len(self.data)} columns; index {self.index}>")


# metadata sections that are mappings in every file hemocircuit writes
_MAPPING_SECTIONS = ("provenance", "settings", "solver", "measures")

# analyses whose default plot is not a plain series plot (analysis name -> module)
_PLOTTERS = {"ac": "hemocircuit.analyses.ac", "freq": "hemocircuit.analyses.freq",
             "envelope": "hemocircuit.analyses.envelope", "stability": "hemocircuit.analyses.stability"}


def _json_line(v):
    return json.dumps(jsonable(v), separators=(", ", ": "))


def _parse_json_line(text):
    try:
        return json.loads(text)
    except ValueError:
        return text


def _typed(cells):
    """Cells read back from a file -> an int, float, bool or text array."""
    if cells and all(_INT.match(c) for c in cells):
        return np.array([int(c) for c in cells])
    try:
        return np.array([float(c) for c in cells], dtype=float)
    except ValueError:
        pass
    if cells and all(c in ("True", "False") for c in cells):
        return np.array([c == "True" for c in cells])
    return np.array(cells, dtype=object)
