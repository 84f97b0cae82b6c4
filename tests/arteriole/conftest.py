"""Load the arteriole package as installed (hemocircuit.components.arteriole) or, before the
package is installed, straight from components/arteriole/ (the package-dir mapping of
pyproject.toml), and hand it to the tests as the ``art`` fixture."""
import importlib
import importlib.util
import sys
from pathlib import Path

import pytest

_PKG_DIR = Path(__file__).resolve().parents[2] / "components" / "arteriole"


def _load():
    try:
        return importlib.import_module("hemocircuit.components.arteriole")
    except ImportError:
        name = "_arteriole_under_test"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(
            name, _PKG_DIR / "__init__.py", submodule_search_locations=[str(_PKG_DIR)])
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
        return mod


@pytest.fixture(scope="session")
def art():
    return _load()


@pytest.fixture(scope="session")
def kuo(art):
    return art.make_params("kuo91")

