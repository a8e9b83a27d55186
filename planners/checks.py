"""Checks shared by the parameter dataclasses' ``validate()``; each error names the field."""

from __future__ import annotations


def require_positive(obj: object, *names: str) -> None:
    """Raise ValueError naming the first of the fields ``names`` of ``obj`` that is not > 0."""
    for name in names:
        if not getattr(obj, name) > 0:
            raise ValueError(f"{name} must be > 0")


def require_non_negative(obj: object, *names: str) -> None:
    """Raise ValueError naming the first of the fields ``names`` of ``obj`` that is not >= 0."""
    for name in names:
        if not getattr(obj, name) >= 0:
            raise ValueError(f"{name} must be >= 0")
