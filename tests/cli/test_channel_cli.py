"""`colsim pack`, `trim` and `collapse` of a channel (geometry channel): the files say which geometry
they hold, and the channel's settings are refused in one line where they cannot hold."""
from __future__ import annotations

import subprocess
import sys

import pytest
import xarray as xr


def colsim(*args, cwd):
    return subprocess.run([sys.executable, "-m", "colsim.cli", "-q", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_a_channel_s_files_name_its_geometry(tmp_path):
    """A tiny channel (L0 = 1, W = 0.8, a = 1; about ten spheres) through the three stages: each file
    carries geometry channel, channel_length and channel_width, the collapse wall_mu too, and r0 holds
    L0 (r0's role: h0 = a L0)."""
    for args in (["pack", "--geometry", "channel", "--channel-length", "1", "--channel-width", "0.8", "--height", "1",
                  "--seed", "3", "--output", "pack.nc"],
                 ["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "column.nc"],
                 ["collapse", "--input", "column.nc", "--steps", "5", "--duration", "0.05", "--wall-mu", "0.2",
                  "--output", "collapse.nc"]):
        done = colsim(*args, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
    for name in ("pack.nc", "column.nc", "collapse.nc"):
        with xr.open_dataset(tmp_path / name) as dataset:
            attrs = dataset.attrs
            assert (attrs["geometry"], attrs["channel_length"], attrs["channel_width"], attrs["r0"]) == (
                "channel", 1.0, 0.8, 1.0), name
    with xr.open_dataset(tmp_path / "collapse.nc") as dataset:
        assert dataset.attrs["wall_mu"] == 0.2 and dataset.attrs["h0"] == 1.0


@pytest.mark.parametrize("args, words", [
    (["--geometry", "channel", "--channel-length", "1", "--channel-width", "0.3"], "channel_width W = 0.3 is below"),
    (["--channel-length", "1"], "channel_length set a channel, but geometry is cylinder"),
    (["--geometry", "channel", "--channel-width", "1"], "geometry channel needs channel_length (L0) and channel_width"),
    (["--geometry", "channel", "--channel-length", "0", "--channel-width", "1"], "--channel-length: must be > 0"),
])
def test_a_channel_s_bad_settings_stop_the_pour_in_one_line(tmp_path, args, words):
    done = colsim("pack", "--height", "1", *args, "--output", "pack.nc", cwd=tmp_path)
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode != 0 and words in last and not (tmp_path / "pack.nc").exists(), done.stderr
