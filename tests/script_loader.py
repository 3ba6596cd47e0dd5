"""Load a script under ``benchmarks/`` (scripts, not a package) as a module, for its tests.

``load_script("benchmarks/studies/lead.py")`` runs the file once and registers the module in
``sys.modules`` as ``script_lead`` (dataclasses look their module up there); a second call
for the same file returns the same module.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[1]


def load_script(relpath: str) -> ModuleType:
    """The module of the script at ``relpath`` (relative to the repository root)."""
    path = REPO / relpath
    name = f"script_{path.stem}"
    loaded = sys.modules.get(name)
    if loaded is not None and Path(loaded.__file__ or "") == path:
        return loaded
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
