"""Writing figures: :func:`save`, the one way every figure builder's result goes to disk.

The figure builders (``*_figure``) return a matplotlib Figure unsaved; callers write it
with ``save(builder(...), out_path)``. ``plt`` here is pyplot on the Agg backend (set by
the package, :mod:`cosim.analysis.figures`, before any of its modules loads pyplot).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

#: Resolution of saved PNG figures, dots per inch.
SAVE_DPI = 120


def save(fig, out_path: str | Path) -> Path:
    """Write ``fig`` to ``out_path`` (PNG at :data:`SAVE_DPI`, tight bounding box; parent
    folders made), close it and return the path."""
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=SAVE_DPI, bbox_inches="tight")
    plt.close(fig)
    return out


__all__ = ["SAVE_DPI", "plt", "save"]
