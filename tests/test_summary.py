"""The summary's CSV form: one row per run, whatever extra dimensions the checks have."""
import numpy as np
import pytest

xr = pytest.importorskip("xarray")

from colsim.summary import one_row_per_run  # noqa: E402


def test_check_variables_become_one_column_per_value():
    dims = ("aspect_ratio", "mu_r", "seed")
    summary = xr.Dataset(
        {"h_inf_over_r0": (dims, np.ones((2, 1, 1))),
         "runout_over_r0_by_tolerance": (dims + ("contact_tolerance",), [[[[1.0, 1.5]]], [[[2.0, 2.5]]]]),
         "mass_front_over_r0": (dims + ("mass_share",), [[[[3.0]]], [[[4.0]]]], {"units": "1"})},
        coords={"aspect_ratio": [1.0, 2.0], "mu_r": [0.12], "seed": [1], "contact_tolerance": [0.01, 0.5],
                "mass_share": [0.95]})
    table = one_row_per_run(summary).to_dataframe()
    assert len(table) == 2
    assert list(table.columns) == ["h_inf_over_r0", "runout_over_r0_by_tolerance_0.01",
                                   "runout_over_r0_by_tolerance_0.5", "mass_front_over_r0_0.95"]
    assert table["runout_over_r0_by_tolerance_0.5"].tolist() == [1.5, 2.5]
    assert one_row_per_run(summary)["mass_front_over_r0_0.95"].attrs["units"] == "1"
