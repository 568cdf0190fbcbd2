"""The trim stage (colsim.stages.trim): the packing cut at h0 = a r0."""
from __future__ import annotations

import pytest

from colsim.stages.trim import trim

from helpers import PACKING_R0 as R0


def test_trim_keeps_spheres_below_h0_and_fails_loudly_when_too_short(packing):
    h0 = 1.0 * R0
    column = trim(packing.state, h0)
    top = column.position[:, 2] + column.radius
    assert top.max() <= h0
    # an undisturbed top reads as h0 to within one smallest diameter
    assert top.max() > h0 - 0.25
    with pytest.raises(ValueError, match="too short"):
        trim(packing.state, 10.0)
