"""Benchmarks shipped with ukemi: ``python -m ukemi.cli bench accuracy`` (see :mod:`.accuracy`)."""

from __future__ import annotations

__all__ = ["accuracy"]
