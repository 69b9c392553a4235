"""Where the real benchmark graphs are: ``../shared/datasets`` beside the project checkout.

They are never copied into the project (licences vary). Set ``LAGO_CVX_DATASETS`` to use another
folder. Code that needs them calls ``dataset("carlone/INTEL_P_toro.graph")`` and handles
``DatasetNotFound`` (the lectures say so clearly and fall back to a synthetic world).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["datasets_dir", "dataset", "DatasetNotFound"]


class DatasetNotFound(FileNotFoundError):
    """The datasets folder or a file in it is absent."""


def _candidates() -> list[Path]:
    out = []
    env = os.environ.get("LAGO_CVX_DATASETS")
    if env:
        out.append(Path(env))
    root = Path(__file__).resolve().parents[1]  # the project checkout (editable install)
    out.append(root.parent / "shared" / "datasets")
    cwd = Path.cwd().resolve()
    out += [cwd.parent / "shared" / "datasets", cwd.parent.parent / "shared" / "datasets"]
    return out


def datasets_dir() -> Path | None:
    """The datasets folder, or None when it is not found."""
    for c in _candidates():
        if c.is_dir():
            return c
    return None


def dataset(rel: str) -> Path:
    """Path of a dataset file (e.g. ``"se-sync/MIT.g2o"``); raises ``DatasetNotFound`` with the places tried."""
    base = datasets_dir()
    if base is None:
        tried = ", ".join(str(c) for c in _candidates())
        raise DatasetNotFound(f"real datasets not found (tried {tried}); set LAGO_CVX_DATASETS")
    p = base / rel
    if not p.is_file():
        raise DatasetNotFound(f"dataset {rel} not found under {base}")
    return p
