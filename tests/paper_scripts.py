"""A paper's script (``papers/NAME/tuning.py`` and the like) loaded by path for its tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType


def paper_script(path: Path, name: str) -> ModuleType:
    """The script at ``path``, loaded once as module ``name`` (kept in ``sys.modules``, so a
    worker process that unpickles its functions by module name finds the same module)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
