"""Number formats of the Markdown reports: fixed decimals, signed differences, intervals, p-values.

Every formatter prints ``-`` for a value that is not a finite number (None,
NaN, infinity, a string), so a missing cell never raises.
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path

__all__ = [
    "num",
    "fixed",
    "interval",
    "estimate",
    "signed",
    "p_value",
    "ms",
    "model_key",
    "kind_name",
]


def num(x) -> bool:
    """True for a finite real number (Python or NumPy scalar), False for a bool and the rest."""
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)


def fixed(x, nd: int = 3) -> str:
    return f"{x:.{nd}f}" if num(x) else "-"


def interval(lo_hi, nd: int = 3) -> str:
    if not lo_hi or not all(num(v) for v in lo_hi):
        return ""
    return f" [{lo_hi[0]:.{nd}f}, {lo_hi[1]:.{nd}f}]"


def estimate(x, lo_hi, nd: int = 3) -> str:
    """``x`` with its interval: ``0.512 [0.480, 0.544]``; ``x`` alone when the interval is missing."""
    return fixed(x, nd) + interval(lo_hi, nd)


def signed(x, nd: int = 3) -> str:
    return f"{x:+.{nd}f}" if num(x) else "-"


def p_value(p) -> str:
    if not num(p):
        return "-"
    return "<0.001" if p < 1e-3 else f"{p:.3f}"


def model_key(name: str) -> tuple:
    """PNet_0..PNet_m by index, then PNet_ens, PNet_best-of-N, PNet_cascade, then by name."""
    tail = name.split("_", 1)[-1]
    if tail.isdigit():
        return (0, int(tail), name)
    return ({"ens": 1, "cascade": 3}.get(tail, 2 if tail.startswith("best-of-") else 4), 0, name)


def kind_name(kind: str) -> str:
    return {"uniform": "uniform", "nontrivial": "non-trivial"}.get(kind, kind)


def ms(x) -> str:
    return f"{1e3 * x:.2f}" if num(x) else "-"


def _tex_model(m: str) -> str:
    """``$\\mathsf{PNet}_3$``, ``$\\mathsf{PNet}_\\mathsf{best\\mbox{-}of\\mbox{-}4}$``, ..."""
    idx = m.split("_", 1)[-1]  # PNet_0 .. PNet_3, PNet_ens, PNet_best-of-4, PNet_cascade
    if not m.startswith("PNet_"):
        return m
    idx = idx if idx.isdigit() else "\\mathsf{" + idx.replace("-", "\\mbox{-}") + "}"
    return f"$\\mathsf{{PNet}}_{idx}$"


def root_label(root) -> str:
    """``root`` as the repository spells it (from its ``results`` folder on), whatever the
    working directory."""
    parts = Path(root).resolve().parts
    return "/".join(parts[parts.index("results") :]) if "results" in parts else Path(root).name


def stale_page(path: Path, rendered: str, root) -> str | None:
    """None if the page at ``path`` is ``rendered``, else why not (one line naming the
    command that regenerates the page of results root ``root``)."""
    current = path.read_text(encoding="utf-8") if path.exists() else None
    if current == rendered:
        return None
    what = "is missing" if current is None else "is out of date"
    return (
        f"{path} {what}; regenerate it with python scripts/reproduce.py --report-only "
        f"--results {root}"
    )
