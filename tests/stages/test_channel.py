"""The channel geometry of the stages: a pour into the box behind the gate, its cut at h0 = a L0, its
collapse along the channel once the gate is removed, and the channel settings refused in one line."""
from __future__ import annotations

import re

import numpy as np
import pytest

from colsim.engine.contacts import overlaps
from colsim.engine.state import PLANE, Walls, channel_planes
from colsim.solvers import ClarabelSolver
from colsim.stages.collapse import collapse
from colsim.stages.pack import pack, pour_walls
from colsim.stages.pour_geometry import (LATTICE_FACTOR, Channel, footprint_area, footprint_of, geometry_attributes,
                                         lattice_layer, solid_fraction)
from colsim.stages.settings import CollapseSettings, PackSettings, by_name
from colsim.stages.trim import trim

CHANNEL = Channel(length=1.5, width=2.0)


@pytest.fixture(scope="module")
def channel_packing():
    """About 180 spheres poured into a channel's box of L0 = 1.5 and W = 2 (about 5 mean diameters),
    2 high, with Clarabel (a few seconds)."""
    settings = PackSettings(geometry="channel", channel_length=CHANNEL.length, channel_width=CHANNEL.width, height=2.0)
    return pack(settings, np.random.default_rng([7, 0]), ClarabelSolver())


def test_a_channel_pour_fills_its_box_as_densely_as_a_cylinder(channel_packing):
    """The pour settles taller than asked, inside the box (its walls' overlaps within the stepper's
    1 % of the smallest diameter), at a solid fraction within the cylinder's range
    (stages/test_pack: 0.52-0.66, the cylinder pours' spread; the walls loosen the packing near them, so
    a channel about 5 diameters wide lies in the lower half)."""
    state = channel_packing.state
    assert channel_packing.height > 2.0 and state.n > 100
    walls = Walls(floor=True, planes=channel_planes(CHANNEL.length, CHANNEL.width, gate=True))
    assert overlaps(state, walls).largest_plane <= 0.01 * 2 * state.radius.min()
    assert 0.52 < channel_packing.solid_fraction < 0.66
    assert channel_packing.solid_fraction == solid_fraction(state, CHANNEL, 2.0)


def test_a_channel_collapses_along_its_axis_between_its_walls(channel_packing):
    """The column cut at h0 = a L0 (a = 1) and released with the gate removed: after 50 steps of
    dt = 0.02 sqrt(h0/g) (t = sqrt(h0/g)) the front has left the box along +x, and no sphere has
    crossed the back wall or a sidewall (the stepper's 1 % of the smallest diameter), nor moved sideways
    past them; the sidewalls carry contacts of the wall family."""
    h0 = 1.0 * CHANNEL.length
    column = trim(channel_packing.state, h0)
    settings = CollapseSettings(duration=1.0, n_steps=50, wall_mu=0.3)
    run = collapse(column, h0, settings, ClarabelSolver(), channel=CHANNEL)
    final = run.frames[-1][1]
    tolerance = 0.01 * 2 * final.radius.min()
    # the front: in the box at release, then past the gate's place by more than the smallest radius
    # (it moved 0.15 here, about a diameter; its centre of mass moved along +x only)
    assert float(np.max(column.position[:, 0] + column.radius)) <= CHANNEL.length
    assert float(np.max(final.position[:, 0] + final.radius)) > CHANNEL.length + final.radius.min()
    assert np.mean(final.position[:, 0]) > np.mean(column.position[:, 0])
    assert float(np.min(final.position[:, 0] - final.radius)) >= -tolerance
    assert float(np.max(np.abs(final.position[:, 1]) + final.radius)) <= 0.5 * CHANNEL.width + tolerance
    assert max(d.largest_overlap for d in run.diagnostics) <= tolerance
    walls = settings.step_settings(h0, CHANNEL).walls
    assert walls.planes == channel_planes(CHANNEL.length, CHANNEL.width, gate=False)
    assert settings.law(channel=True).mu == (0.577, 0.577, 0.3)


def test_a_box_s_lattice_lies_inside_it():
    """The pour's lattice in a box: whole cells of side 1.04 d_max, as many as fit along each side."""
    spacing = LATTICE_FACTOR * 0.5
    cells = lattice_layer(CHANNEL, spacing)
    assert len(cells) == int(CHANNEL.length // spacing) * int(CHANNEL.width // spacing)
    assert cells[:, 0].min() - spacing / 2 >= 0 and cells[:, 0].max() + spacing / 2 <= CHANNEL.length
    assert np.abs(cells[:, 1]).max() + spacing / 2 <= CHANNEL.width / 2
    assert footprint_area(CHANNEL) == 3.0 and footprint_area(2.0) == pytest.approx(4 * np.pi)


def test_a_channel_s_settings_reach_its_files_and_a_cylinder_s_files_keep_theirs():
    """A cylinder's packing records no geometry setting (its files and keys as before channels); a
    channel's records geometry, channel_length and channel_width, and its files' attributes name them."""
    cylinder = PackSettings(height=1.0)
    channel = PackSettings(height=1.0, geometry="channel", channel_length=1.5, channel_width=2.0)
    assert not {"geometry", "channel_length", "channel_width"} & set(by_name(cylinder))
    assert {"geometry": "channel", "channel_length": 1.5, "channel_width": 2.0}.items() <= by_name(channel).items()
    assert "wall_mu" not in by_name(CollapseSettings()) and by_name(CollapseSettings(wall_mu=0.2))["wall_mu"] == 0.2
    assert geometry_attributes(cylinder.footprint) == {} and footprint_of({"r0": 3.0}) == 3.0
    attributes = {"r0": 1.5, **geometry_attributes(channel.footprint)}
    assert footprint_of(attributes) == Channel(1.5, 2.0) and channel.length_scale == 1.5
    assert pour_walls(channel.footprint).planes[-1] == (-1.0, 0.0, 0.0, -1.5)   # the gate


@pytest.mark.parametrize("settings, words", [
    ({"geometry": "channel", "channel_length": 1.5, "channel_width": 0.3}, "channel_width W = 0.3 is below 1.04"),
    ({"geometry": "channel", "channel_length": 0.0, "channel_width": 1.0}, "channel_length L0 must be positive"),
    ({"geometry": "channel", "channel_length": -1.0, "channel_width": 1.0}, "channel_length L0 must be positive"),
    ({"geometry": "channel", "channel_length": 1.5}, "geometry channel needs channel_length (L0) and channel_width"),
    ({"channel_length": 1.5}, "channel_length set a channel, but geometry is cylinder"),
    ({"channel_width": 1.0, "channel_length": 1.5}, "channel_length and channel_width set a channel"),
    ({"geometry": "box"}, "geometry must be one of cylinder, channel"),
])
def test_bad_channel_settings_are_refused_in_one_line(settings, words):
    with pytest.raises(ValueError, match=re.escape(words)) as error:
        PackSettings(height=1.0, **settings)
    assert "\n" not in str(error.value)


def test_a_negative_wall_friction_or_one_on_a_cylinder_is_refused():
    with pytest.raises(ValueError, match="friction coefficient wall_mu must be >= 0"):
        CollapseSettings(wall_mu=-0.1)
    column = trim(pack(PackSettings(r0=0.8, height=0.8, max_steps=200), np.random.default_rng([1, 0]),
                       ClarabelSolver()).state, 0.8)
    with pytest.raises(ValueError, match="wall_mu is the friction of a channel's walls; this column is a cylinder"):
        collapse(column, 0.8, CollapseSettings(wall_mu=0.3, n_steps=2, duration=0.01), ClarabelSolver())


def test_a_plane_s_contacts_carry_its_own_family():
    """Each of a channel's planes has a family of its own (PLANE + p), in channel_planes' order."""
    assert [PLANE + p for p, _ in enumerate(channel_planes(1.0, 1.0, gate=True))] == [3, 4, 5, 6]
