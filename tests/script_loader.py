"""``load_script(name)``: a fresh module of ``scripts/<name>.py``, for tests that call a
script's ``main`` (or its helpers) in this process."""

import importlib.util
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def load_script(name: str, module_name: str | None = None):
    """``scripts/<name>.py`` executed as a new module named ``module_name`` (default ``name``)."""
    spec = importlib.util.spec_from_file_location(module_name or name, SCRIPTS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
