"""The parameter checks every validate() shares."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

from planners.checks import require_non_negative, require_positive


@dataclass(frozen=True)
class Two:
    a: float = 1.0
    b: float = 0.0


def test_require_positive_names_the_first_field_not_above_zero() -> None:
    require_positive(Two(), "a")
    with pytest.raises(ValueError, match=r"^b must be > 0$"):
        require_positive(Two(), "a", "b")
    with pytest.raises(ValueError, match=r"^a must be > 0$"):
        require_positive(Two(a=math.nan), "a")


def test_require_non_negative_lets_zero_pass() -> None:
    require_non_negative(Two(), "a", "b")
    with pytest.raises(ValueError, match=r"^b must be >= 0$"):
        require_non_negative(Two(b=-0.1), "a", "b")
