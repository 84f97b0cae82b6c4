"""Immutable, batched parameter values of one circuit structure.

A :class:`ParameterSet` holds the numeric value of every ``ID.PARAM`` of a circuit for a batch
of ``B`` members (a single run is ``B == 1``), plus the waveforms set on parameters.  It never
changes: :meth:`ParameterSet.with_values` returns a new set, and every array it hands out is
read-only.  ``Circuit.with_values`` / ``Circuit.with_parameters`` turn a set into a circuit.

Values are stored per group of elements (one type and option set; the circuit's evaluation
order), as arrays of shape (1, E) -- the same for every member -- or (B, E).  Values are in
the parameter's declared unit (``Component.parameters[name].unit``): mmHg, mL, s, ... .

Setting a value accepts what ``--set`` and protocols accept: a number in the declared unit, a
quantity string with a unit ("5 s"), a pint quantity, a waveform mapping
({sine: ...}; see hemocircuit.waveforms), or an array of B numbers (one per member).  On a
parameter that carries a waveform, any value other than a waveform replaces it (as in a
netlist).  Each value is checked against the parameter's bounds (``build.check_values``);
errors name the file, element and parameter.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .build import check_relations, check_values
from .errors import NetlistError
from .units import UnitError, parse_quantity
from .names import split_path


def _digest_into(h, obj):
    """Feed ``obj`` (a group's waveform entries: tuples, waveform dataclasses, arrays, numbers,
    names) into the hash ``h`` in full: every array's bytes and every float's exact repr
    (numpy's repr of a long array elides its middle, and rounds to 8 digits)."""
    import dataclasses

    if isinstance(obj, np.ndarray):
        h.update(f"{obj.dtype}{obj.shape}".encode())
        h.update(np.ascontiguousarray(obj).tobytes())
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(type(obj).__name__.encode())
        for f in dataclasses.fields(obj):
            h.update(f.name.encode())
            _digest_into(h, getattr(obj, f.name))
    elif isinstance(obj, (list, tuple)):
        h.update(b"(")
        for item in obj:
            _digest_into(h, item)
        h.update(b")")
    else:
        h.update(repr(obj).encode())


def _frozen(a):
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


class ParameterSchema:
    """Where each ``ID.PARAM`` lives: the element data (declared units, bounds, expressions)
    and (group index, index in the group).  Shared by every parameter set of a structure."""

    def __init__(self, file, elements: dict, groups: list):
        self.file = file
        self.elements = elements  # id -> ElementData (as assembled)
        self.group_ids = [list(ids) for ids in groups]  # per group: element ids, in order
        self.locate = {eid: (gi, i) for gi, ids in enumerate(self.group_ids) for i, eid in enumerate(ids)}

    def resolve(self, path: str):
        """'ID.PARAM' -> (element data, group index, index in group, name); clear errors."""
        if not isinstance(path, str) or "." not in path:
            raise NetlistError(f"parameter path {path!r} must be ID.PARAM", file=self.file)
        eid, name = split_path(path)
        if eid not in self.elements:
            raise NetlistError(f"no element '{eid}' (elements: {sorted(self.elements)})", file=self.file,
                               element=eid)
        e = self.elements[eid]
        gi, i = self.locate[eid]
        if name not in e.cls.parameters:
            if name in e.cls.options:
                raise NetlistError(f"'{name}' is a structural option; change it with Circuit.with_options "
                                   "(or in the netlist / protocol 'initial')", file=e.file, element=eid)
            raise NetlistError(f"no parameter '{name}'; '{e.cls.type_name}' has {sorted(e.cls.parameters)}",
                               file=e.file, element=eid)
        return e, gi, i, name

    def paths(self):
        """Every settable ID.PARAM (parameters that follow an expression excluded), in
        evaluation order."""
        for ids in self.group_ids:
            for eid in ids:
                e = self.elements[eid]
                for name in e.cls.parameters:
                    if name not in e.expressions:
                        yield f"{eid}.{name}"


class ParameterValues(Mapping):
    """Read-only mapping ``ID.PARAM -> array (B,)`` in the declared unit (``ps.values``)."""

    def __init__(self, ps: "ParameterSet"):
        self._ps = ps

    def __getitem__(self, path):
        ps = self._ps
        e, gi, i, name = ps.schema.resolve(path)
        if name in e.expressions:
            raise NetlistError(f"'{name}' follows the expression '{e.expressions[name].text}': it has no fixed "
                               "value (it is evaluated from the states; see the outputs)", file=e.file, element=e.id)
        return _frozen(np.broadcast_to(ps._arrays[gi][name][:, i], (ps.B,)))

    def __iter__(self):
        return self._ps.schema.paths()

    def __len__(self):
        return sum(1 for _ in self._ps.schema.paths())


class ParameterSet:
    """Parameter values of B members for one circuit structure (immutable; see module doc)."""

    __slots__ = ("schema", "B", "_arrays", "_waves", "_digest")

    def __init__(self, schema: ParameterSchema, B: int, arrays, waves):
        # arrays: per group {name: read-only (1 or B, E)}; waves: per group ((i, name, wf), ...)
        self.schema = schema
        self.B = int(B)
        self._arrays = tuple(arrays)
        self._waves = tuple(tuple(w) for w in waves)
        self._digest = None  # fingerprint(), once

    def __setstate__(self, state):
        """Unpickled: the slots as pickled, the value arrays read-only again (pickle gives
        writable arrays; the set is immutable, and its fingerprint is kept)."""
        for name, value in (state[1] if isinstance(state, tuple) else state).items():
            setattr(self, name, value)
        for arrays in self._arrays:
            for a in arrays.values():
                if isinstance(a, np.ndarray):
                    a.flags.writeable = False

    @classmethod
    def from_elements(cls, schema: ParameterSchema) -> "ParameterSet":
        """The values and waveforms the netlist gives (one member)."""
        arrays, waves = [], []
        for ids in schema.group_ids:
            es = [schema.elements[eid] for eid in ids]
            arrays.append({name: _frozen([[e.values[name] for e in es]]) for name in es[0].cls.parameters})
            waves.append([(i, name, wf) for i, e in enumerate(es) for name, wf in e.waveforms.items()])
        return cls(schema, 1, arrays, waves)

    # ------------------------------------------------------------------ reading -------
    @property
    def values(self) -> ParameterValues:
        """``ps.values['Pa.value']`` -> read-only array (B,) in the declared unit.  A parameter
        driven by a waveform reports its stored base value (a source's is 0: the waveform is
        added to it); see :meth:`waveform`."""
        return ParameterValues(self)

    def unit(self, path: str) -> str:
        e, _, _, name = self.schema.resolve(path)
        return e.cls.parameters[name].unit

    def waveform(self, path: str):
        """The waveform set on ID.PARAM (hemocircuit.waveforms), or None."""
        _, gi, i, name = self.schema.resolve(path)
        return next((wf for j, n, wf in self._waves[gi] if j == i and n == name), None)

    def constant(self, path: str, what: str) -> float:
        """The value of ID.PARAM (its first member's) for ``what`` (an analysis that varies it as
        a number: a fit, a sensitivity study); an error naming it when the parameter carries a
        waveform, whose time course a number would replace (``with_values``)."""
        if self.waveform(path) is not None:
            e, *_ = self.schema.resolve(path)
            raise NetlistError(f"{what}: {path} carries a waveform (its value varies in time), which a number would "
                               f"replace; vary a constant parameter, or set {path} to a constant first "
                               f"(--set {path}=VALUE)", file=e.file, element=e.id)
        return float(self.values[path][0])

    def group_arrays(self, gi: int) -> dict:
        """{name: read-only (1 or B, E)} of group ``gi`` (the circuit's evaluation layout)."""
        return self._arrays[gi]

    def group_waves(self, gi: int) -> tuple:
        """((index in group, name, waveform), ...) of group ``gi``."""
        return self._waves[gi]

    # ------------------------------------------------------------------ changing ------
    def with_values(self, mapping: Mapping) -> "ParameterSet":
        """A new set with ``{ID.PARAM: value}`` applied in order (see the module doc for the
        accepted values).  This set is unchanged, also when a value is rejected."""
        arrays = [dict(a) for a in self._arrays]
        waves = [list(w) for w in self._waves]
        touched = {}  # element id -> (element data, group, index)
        for path, value in dict(mapping).items():
            e, gi, i, name = self.schema.resolve(path)
            if name in e.expressions:
                raise NetlistError(f"'{name}' follows an expression ({e.expressions[name].text}); it cannot be set",
                                   file=e.file, element=e.id)
            par = e.cls.parameters[name]
            # a waveform replaces the parameter's waveform, and any other value replaces it too,
            # in whichever form it is given (as in a netlist)
            waves[gi] = [w for w in waves[gi] if not (w[0] == i and w[1] == name)]
            wf = None
            if isinstance(value, dict):  # a waveform (a constant one is just a number)
                from .waveforms import Constant, parse_waveform
                wf = parse_waveform(value, par.unit, None, {"file": e.file, "element": e.id})
                if isinstance(wf, Constant):
                    value, wf = wf.value, None
                else:
                    waves[gi].append((i, name, wf))
                    value = 0.0
            if isinstance(value, str):
                try:
                    value = parse_quantity(value, par.unit, f"{path}")
                except UnitError as exc:
                    raise NetlistError(str(exc), file=e.file, element=e.id) from None
            elif hasattr(value, "to"):  # a pint quantity (scalar or array)
                try:
                    value = np.asarray(value.to(par.unit).magnitude, dtype=float)
                except Exception as exc:  # noqa: BLE001 - pint's DimensionalityError
                    raise NetlistError(f"{path} = {value}: {exc}", file=e.file, element=e.id) from None
            try:
                arr = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise NetlistError(f"{path} = {value!r} is not a number (in {par.unit}), a quantity with a unit, "
                                   "a waveform or an array of one number per member", file=e.file,
                                   element=e.id) from None
            check_values(e, {name: arr}, {name: wf}, relations=False)  # the waveform in effect, not the netlist's
            arrays[gi][name] = self._column(arrays[gi][name], i, arr, path, e)
            touched[e.id] = (e, gi, i)
        # the relations between an element's values (Rmin <= Rmax) once the whole mapping is in,
        # on its current values: not the netlist's, nor half a mapping's
        for e, gi, i in touched.values():
            check_relations(e, {n: a[:, i:i + 1] for n, a in arrays[gi].items() if n not in e.expressions})
        return ParameterSet(self.schema, self.B, arrays, waves)

    def _column(self, cur, i, arr, path, e):
        """cur (1 or B, E) with column i replaced by arr (scalar or (B,)); read-only copy."""
        if arr.ndim == 0:
            new = np.array(cur)
        else:
            if arr.shape != (self.B,):
                raise NetlistError(f"{path}: expected one value per member ({self.B}), got shape {arr.shape}",
                                   file=e.file, element=e.id)
            new = np.repeat(cur, self.B, axis=0) if cur.shape[0] == 1 else np.array(cur)
        new[:, i] = arr
        new.flags.writeable = False
        return new

    def with_columns(self, updates) -> "ParameterSet":
        """Raw replacement of already checked values: [(gi, i, name, column (1 or B,), waveform
        or None)]; the waveform replaces any other on that parameter.  (Circuit.with_options
        carries values over to a re-assembled structure with it.)"""
        arrays = [dict(a) for a in self._arrays]
        waves = [list(w) for w in self._waves]
        for gi, i, name, col, wf in updates:
            cur = arrays[gi][name]
            rows = max(cur.shape[0], np.shape(col)[0])
            new = np.array(np.broadcast_to(cur, (rows, cur.shape[1])))
            new[:, i] = col
            new.flags.writeable = False
            arrays[gi][name] = new
            waves[gi] = [w for w in waves[gi] if not (w[0] == i and w[1] == name)]
            if wf is not None:
                waves[gi].append((i, name, wf))
        return ParameterSet(self.schema, self.B, arrays, waves)

    # ------------------------------------------------------------------ members -------
    def __getitem__(self, key) -> "ParameterSet":
        """``ps[k]``: member k (B = 1); ``ps[members]`` (slice, sequence or index array,
        repeats allowed): those members in that order."""
        if isinstance(key, (int, np.integer)):
            k = int(key)
            if not -self.B <= k < self.B:
                raise IndexError(f"member {k} of a parameter set of {self.B}")
            idx = np.array([k % self.B])
        elif isinstance(key, slice):
            idx = np.arange(self.B)[key]
        else:
            idx = np.asarray(key)
            if idx.dtype == bool:
                idx = np.nonzero(idx)[0]
            idx = idx.astype(int).reshape(-1)
            if idx.size and (idx.min() < -self.B or idx.max() >= self.B):
                raise IndexError(f"members {idx.tolist()} of a parameter set of {self.B}")
            idx = idx % self.B if idx.size else idx
        arrays = [{n: (_frozen(v[idx]) if v.shape[0] > 1 else v) for n, v in a.items()} for a in self._arrays]
        return ParameterSet(self.schema, len(idx), arrays, self._waves)

    def members(self):
        """Iterate over the members as single-member sets."""
        for k in range(self.B):
            yield self[k]

    @classmethod
    def stack(cls, sets) -> "ParameterSet":
        """One batch made of the members of ``sets`` (in order).  All must belong to one
        structure and carry the same waveforms (waveforms are shared by a batch)."""
        sets = list(sets)
        if not sets:
            raise ValueError("ParameterSet.stack needs at least one parameter set")
        first = sets[0]
        for s in sets[1:]:
            if s.schema is not first.schema:
                raise NetlistError("ParameterSet.stack: the sets belong to different circuit structures")
            if s._waves != first._waves:
                raise NetlistError("ParameterSet.stack: the sets carry different waveforms (a batch shares its "
                                   "waveforms; vary numeric parameters only)")
        B = sum(s.B for s in sets)
        arrays = []
        for gi, a in enumerate(first._arrays):
            arrays.append({n: _frozen(np.concatenate([np.broadcast_to(s._arrays[gi][n], (s.B, v.shape[1]))
                                                      for s in sets]))
                           for n, v in a.items()})
        return cls(first.schema, B, arrays, first._waves)

    def fingerprint(self) -> str:
        """A digest of every value and waveform (equal sets have equal fingerprints: a key
        for memos of results that depend only on the values; computed once: the set is
        immutable, and every operating point asks for it)."""
        digest = getattr(self, "_digest", None)
        if digest is None:
            digest = self._digest = self._hash()
        return digest

    def _hash(self) -> str:
        import hashlib

        h = hashlib.sha1(str(self.B).encode())
        for a, w in zip(self._arrays, self._waves):
            for n in sorted(a):
                h.update(n.encode())
                h.update(str(a[n].shape).encode())
                h.update(np.ascontiguousarray(a[n]).tobytes())
            _digest_into(h, w)
        return h.hexdigest()

    def __eq__(self, other):
        if not isinstance(other, ParameterSet):
            return NotImplemented
        return (self.schema is other.schema and self.B == other.B and self._waves == other._waves
                and all(np.array_equal(np.broadcast_to(a[n], (self.B, a[n].shape[1])),
                                       np.broadcast_to(b[n], (self.B, b[n].shape[1])), equal_nan=True)
                        for a, b in zip(self._arrays, other._arrays) for n in a))

    __hash__ = None

    def __repr__(self):
        return f"<ParameterSet: {self.B} member(s), {len(self.values)} parameters>"
