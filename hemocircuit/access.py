"""Which folders a netlist may read other files from (``extends:``, table ``file:``).

A netlist names files relative to its own folder.  It may read only inside the *allowed
folders*: the project of the netlist given on the command line (the nearest folder above it
that holds a ``pyproject.toml`` or ``.git``, else the netlist's own folder), the netlists
bundled with hemocircuit, the folder of a protocol file given on the command line (for that
protocol's tables), and any folder given with ``--allow-path DIR`` (API: ``allow_paths=``).
So ``extends: /etc/shadow`` or ``file: ../../../home/me/.ssh/id_rsa`` is refused before the
file is opened, and nothing of it can appear in an error message.  Symbolic links are
followed before the check.
"""
from __future__ import annotations

import os

from .errors import NetlistError

_MARKERS = ("pyproject.toml", ".git")
BUNDLED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "netlists")


def project_root(path) -> str:
    """The nearest folder at or above ``path``'s folder holding pyproject.toml or .git (never the
    file-system root or the home folder), else ``path``'s own folder."""
    start = os.path.dirname(os.path.realpath(path))
    home = os.path.realpath(os.path.expanduser("~"))
    d = start
    while True:
        if d in ("/", home) or os.path.dirname(d) == d:
            return start
        if any(os.path.exists(os.path.join(d, m)) for m in _MARKERS):
            return d
        d = os.path.dirname(d)


class Access:
    """The allowed folders (real paths) of one load."""

    def __init__(self, folders):
        self.folders = []
        for f in folders:
            r = os.path.realpath(str(f))
            if r not in self.folders:
                self.folders.append(r)

    @classmethod
    def for_netlist(cls, path, allow_paths=None) -> "Access":
        folders = [project_root(path)]
        if os.path.isdir(BUNDLED):
            folders.append(BUNDLED)
        return cls(folders + [str(p) for p in (allow_paths or [])])

    def with_folder(self, folder) -> "Access":
        return Access(self.folders + [folder])

    def allows(self, path) -> bool:
        if "\x00" in str(path):
            return False  # no file has such a name
        real = os.path.realpath(path)
        return any(real == f or real.startswith(f.rstrip(os.sep) + os.sep) for f in self.folders)

    def resolve(self, name, base_dir, what, where) -> str:
        """``name`` (as written in the file in ``base_dir``) as an absolute path, checked against
        the allowed folders."""
        from .inputs import check_path
        check_path(name, what)
        path = os.path.normpath(name if os.path.isabs(name) else os.path.join(base_dir or ".", name))
        if not self.allows(path):
            raise NetlistError(f"{what} {name!r} is outside the allowed folders {self.folders}; a netlist reads "
                               "files only inside its project (or the bundled netlists): move the file there, or "
                               "allow its folder with --allow-path DIR (API: allow_paths=[DIR])", **where)
        return path
