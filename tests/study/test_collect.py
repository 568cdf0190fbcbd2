"""The summary: collecting analyses (one run per swept value, the rest equal), its CSV form with one
row per run, and its tables against Lube's laws."""
import json

import numpy as np
import pytest
import xarray as xr

from colsim.study.experimental_laws import lube_height, lube_runout
from colsim.study.collect import collect_analyses, counted, one_row_per_run, one_run, run_key, run_status
from colsim.study.markdown import lube_markdown, lube_rst


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


def test_lube_table_reports_zero_error_on_the_law_itself():
    """Lube's own values give +0 % against Lube, and the stated errors against Lajeunesse."""
    ratios = np.array([0.5, 2.0, 5.0])
    h = np.stack([lube_height(ratios)] * 2, axis=-1)[:, None, :]
    r = np.stack([lube_runout(ratios)] * 2, axis=-1)[:, None, :]
    dims = ("aspect_ratio", "mu_r", "seed")
    summary = xr.Dataset({"h_inf_over_r0": (dims, h), "runout_over_r0": (dims, r)},
                         coords={"aspect_ratio": ratios, "mu_r": [0.12], "seed": [1, 2]})
    text = lube_markdown(summary)
    assert "mean of 2 seeds" in text
    assert text.count("+0 %") == 7  # six against Lube, and a = 0.5's height against Lajeunesse (both a)
    assert "| 0.5 | 0.500 | 0.000 | 0.500 | +0 % | 0.620 |" in text
    # Lajeunesse at a = 2: h_inf/r0 = 0.74 a = 1.480, run-out 2 a^0.5 = 2.828
    assert "| 2.263 | +0 % | 1.480 | -33 % | 2.828 | -20 % |" in text
    h[2, 0, 1] = r[2, 0, 1] = np.nan   # a study still running: a = 5 has one seed so far
    partial = summary.assign(h_inf_over_r0=(dims, h), runout_over_r0=(dims, r))
    assert "mean of 1-2 seeds" in lube_markdown(partial)
    h[0, 0, :] = r[0, 0, :] = np.nan   # and a = 0.5 not at all: its row is left out, not NaN
    text = lube_markdown(summary.assign(h_inf_over_r0=(dims, h), runout_over_r0=(dims, r)))
    assert "| 0.5 |" not in text and "nan" not in text and "mean of 1-2 seeds" in text


def test_the_reports_landing_table_is_valid_rst_at_the_nearest_mu_r():
    """lube_rst: the swept mu_r nearest the one asked for, one row per a with Lube's values and the
    errors, and a table docutils renders (the report's landing page) without a warning."""
    import docutils.core

    ratios = np.array([0.5, 2.0])
    dims = ("aspect_ratio", "mu_r", "seed")
    h = np.stack([lube_height(ratios)] * 2, axis=-1)[:, None, :] * np.array([1.0, 1.1])[:, None, None]
    r = np.stack([lube_runout(ratios)] * 2, axis=-1)[:, None, :]
    summary = xr.Dataset({"h_inf_over_r0": (dims, np.concatenate([h, h], axis=1)),
                          "runout_over_r0": (dims, np.concatenate([r, r], axis=1))},
                         coords={"aspect_ratio": ratios, "mu_r": [0.0, 0.12], "seed": [1, 2]})
    text = lube_rst(summary, 0.13)
    assert "mu_r = 0.12, mean over seeds" in text
    settings = {"report_level": 2, "halt_level": 2}   # a warning is an error
    html = docutils.core.publish_string(text, writer="html", settings_overrides=settings).decode()
    assert html.count("<tr>") == 3 and "+0 %" in html and "+10 %" in html and "0.620" in html

    # issue 48.2: the column size said above the table, the runs' flags in it
    summary.attrs["r0"] = 1.0
    summary["at_rest"] = (dims, np.ones(summary.h_inf_over_r0.shape, dtype=np.int8))
    summary["at_rest"][1, 1, 0] = 0                           # a = 2, mu_r = 0.12, seed 1 still moving
    text = lube_rst(summary, 0.12)
    html = docutils.core.publish_string(text, writer="html", settings_overrides=settings).decode()
    assert "A smoke test, not a result" in html and "still moving (seed 1)" in html and "Flags:" in html
    summary.attrs["r0"] = 3.0
    assert "Not converged in the column size" in lube_rst(summary, 0.12)
    summary.attrs["r0"] = 13.0
    assert "converged" not in lube_rst(summary, 0.12).lower() and "smoke" not in lube_rst(summary, 0.12)


def test_other_runout_measures_are_tabled_against_lube():
    ratios = np.array([2.0])
    runout = lube_runout(ratios)[0]
    dims = ("aspect_ratio", "mu_r", "seed")
    summary = xr.Dataset(
        {"h_inf_over_r0": (dims, [[[1.0]]]), "runout_over_r0": (dims, [[[runout]]]),
         "runout_over_r0_by_tolerance": (dims + ("contact_tolerance",), [[[[runout, 1.1 * runout]]]]),
         "mass_front_over_r0": (dims + ("mass_share",), [[[[0.9 * runout]]]])},
        coords={"aspect_ratio": ratios, "mu_r": [0.12], "seed": [1], "contact_tolerance": [0.01, 0.5],
                "mass_share": [0.95]})
    text = lube_markdown(summary)
    assert "| mu_r | a | Lube | connected, gap <= 1 % d_min | connected, gap <= 50 % d_min | 95 % of the mass |" in text
    assert f"| 0.12 | 2 | {runout:.2f} | {runout:.2f} (+0 %) | {1.1 * runout:.2f} (+10 %) | {0.9 * runout:.2f} (-10 %) |" in text


def law_summary(h_shift, runout_shift, programs, wall):
    """A summary of a = 0.5, 2, 5 (mu_r = 0.12, seeds 1-3) at Lube's laws shifted by the given
    amounts, seed k adding 0.01 (k - 2) to both."""
    ratios = np.array([0.5, 2.0, 5.0])
    jitter = 0.01 * (np.arange(1, 4) - 2)
    dims = ("aspect_ratio", "mu_r", "seed")
    grid = lambda law, shift: (law(ratios)[:, None] + shift + jitter[None, :])[:, None, :]  # noqa: E731
    full = np.full((3, 1, 3), 1.0)
    return xr.Dataset({"h_inf_over_r0": (dims, grid(lube_height, h_shift)),
                       "runout_over_r0": (dims, grid(lube_runout, runout_shift)),
                       "n_main_mass": (dims, 80 * full), "n_particles": (dims, 100 * full),
                       "cone_programs_per_step": (dims, programs * full), "wall_time": (dims, wall * full)},
                      coords={"aspect_ratio": ratios, "mu_r": [0.12], "seed": [1, 2, 3]}, attrs={"r0": 2.0})


def test_friction_laws_are_tabled_side_by_side_against_lube(tmp_path):
    from colsim.study.figures import friction_law_figure
    from colsim.study.collect import friction_law_comparison
    from colsim.study.markdown import friction_law_markdown

    comparison = friction_law_comparison({"associated": law_summary(0.0, 0.0, 1.0, 10.0),
                                          "coulomb": law_summary(0.0, 0.5, 15.0, 110.0)})
    assert list(comparison.friction_law.values) == ["associated", "coulomb"]
    assert comparison.h_inf_over_r0.dims == ("friction_law", "aspect_ratio", "mu_r", "seed")
    text = friction_law_markdown(comparison)
    r2 = lube_runout(2.0)
    assert f"| 2 | associated | 3 | {lube_height(2.0):.3f} (0.010) | {lube_height(2.0):.3f} | +0 % | {r2:.3f} (0.010) |" in text
    assert "| 2 | coulomb | 3 |" in text and f"| {r2 + 0.5:.3f} (0.010) | {r2:.3f} | {100 * 0.5 / r2:+.0f} % | 0.80 | 15.0 | 110 |" in text
    assert friction_law_figure(comparison, tmp_path / "friction_law.png").stat().st_size > 10_000


def flag_summary():
    """a = 0.5, 2 (mu_r = 0.12, seeds 1-3): a = 0.5 seed 2 reached max_duration moving; a = 2 ran to a
    fixed end time (at_rest NaN), seed 1 with energy left, seed 3 with a main mass of 3 of 50 grains."""
    dims = ("aspect_ratio", "mu_r", "seed")
    ones = np.ones((2, 1, 3))
    at_rest = np.array([1.0, 0.0, 1.0, np.nan, np.nan, np.nan]).reshape(2, 1, 3)
    energy = np.array([0.5, 0.5, 1e-3, 0.2, 1e-3, 1e-3]).reshape(2, 1, 3)   # at_rest decides where it is set
    main = np.array([50, 50, 50, 50, 50, 3.0]).reshape(2, 1, 3)
    run_configs = json.dumps([{"command": "analyse", "input_config": {"command": "collapse", "rest_energy": 0.1}}])
    return xr.Dataset({"h_inf_over_r0": (dims, ones), "runout_over_r0": (dims, ones), "at_rest": (dims, at_rest),
                       "final_to_peak_kinetic_energy": (dims, energy), "n_main_mass": (dims, main),
                       "n_particles": (dims, 50 * ones)},
                      coords={"aspect_ratio": [0.5, 2.0], "mu_r": [0.12], "seed": [1, 2, 3]},
                      attrs={"run_configs": run_configs})


def test_runs_not_at_rest_or_with_a_fragment_for_main_mass_are_flagged():
    flags = run_status(flag_summary())
    assert flags["moving"].dims == ("aspect_ratio", "mu_r", "seed")
    assert flags["moving"].values.ravel().tolist() == [False, True, False, True, False, False]
    assert flags["fragment"].values.ravel().tolist() == [False, False, False, False, False, True]
    default = flag_summary()
    default.attrs["run_configs"] = "[]"                      # the collapse's default rest_energy, 1e-2
    assert run_status(default)["moving"].values.ravel().tolist() == [False, True, False, True, False, False]
    default["final_to_peak_kinetic_energy"][1, 0, 1] = 0.05
    assert run_status(default)["moving"].values[1, 0, 1]
    bare = flag_summary()[["h_inf_over_r0", "runout_over_r0"]]   # older summaries: nothing to flag by
    assert not any(flag.any() for flag in run_status(bare).values())


def test_one_run_has_the_status_of_its_cell_in_the_summary():
    """run_status of each run alone (its analysis, or its trajectory's step energies) is its cell's in
    the summary: one rule for the tables, the figures' legends and the side views' titles."""
    summary = flag_summary()
    whole = run_status(summary)
    for index in np.ndindex(summary.h_inf_over_r0.shape):
        cell = summary.isel(dict(zip(summary.h_inf_over_r0.dims, index)))
        analysis = cell.drop_vars("at_rest").assign_attrs(config=json.dumps(json.loads(summary.run_configs)[0]))
        if np.isfinite(float(cell.at_rest)):
            analysis["at_rest"] = cell.at_rest.astype(np.int8)
        alone = run_status(one_run(analysis))
        assert {name: bool(flag) for name, flag in alone.items()} == {name: bool(flag[index]) for name, flag in whole.items()}
    # a trajectory: at rest not checked, its steps' energy (translation + rotation) ends at 0.3 of its peak
    trajectory = xr.Dataset({"step_kinetic_energy": ("step", [1.0, 4.0, 1.0]), "step_rotational_energy": ("step", [0.0, 1.0, 0.5])},
                            attrs={"config": json.dumps({"command": "collapse", "rest_energy": 0.25})})
    assert float(one_run(trajectory).final_to_peak_kinetic_energy) == 0.3
    assert bool(run_status(one_run(trajectory))["moving"])
    trajectory.attrs["config"] = json.dumps({"command": "collapse", "rest_energy": 0.5})
    assert not bool(run_status(one_run(trajectory))["moving"])


def test_lube_table_flags_runs_and_says_why():
    text = lube_markdown(flag_summary())
    assert "| Lajeunesse run-out | error | flags |" in text
    assert text.splitlines()[4].endswith("| still moving (seed 2) |")
    assert text.splitlines()[5].endswith("| still moving (seed 1); main mass < half the grains (seed 3) |")
    assert "Flags: *still moving*: the run was not at rest at its end" in text
    assert "above 0.1 of its peak" in text and "less than 50 % of the grains" in text
    settled = flag_summary().assign(at_rest=lambda s: xr.ones_like(s.at_rest), n_main_mass=lambda s: s.n_particles)
    text = lube_markdown(settled)
    assert "Flags:" not in text and text.splitlines()[4].endswith("|  |")


def _analysis(**attrs) -> xr.Dataset:
    """A minimal analysis of one run with these attributes over sane defaults."""
    base = {"aspect_ratio": 2.0, "mu_r": 0.12, "seed": 1, "r0": 3.0, "mu": 0.577,
            "friction_law": "associated", "rolling_lever": "paper", "solver_backends": '{"apgd": 10}'}
    return xr.Dataset({"h_inf_over_r0": ((), 1.0, {"units": "1", "long_name": "h"})}, attrs={**base, **attrs})


def test_collect_takes_every_back_end_a_step_may_record():
    """Clarabel's fallback and APGD's float64 retry of float32 storage are back-ends a step records."""
    backends = '{"apgd": 7, "apgd-float64-fallback": 2, "clarabel-fallback": 1}'
    assert run_key(_analysis(solver_backends=backends)) == (2.0, 0.12, 1)


@pytest.mark.parametrize("attrs, words", [
    ({"rolling_lever": "{{ 7 * 7 }}"}, ["rolling_lever", "paper, effective"]),
    ({"friction_law": ".. include:: /etc/passwd"}, ["friction_law", "associated, coulomb"]),
    ({"solver_backends": '{"<script>": 3}'}, ["solver_backends"]),
    ({"seed": 1.7}, ["seed 1.7", "integer"]),
    ({"seed": 10**30}, ["integer in 0..2^32-1"]),
    ({"aspect_ratio": float("nan")}, ["aspect_ratio", "finite"]),
    ({"mu_r": np.array([0.1, 0.2])}, ["mu_r", "finite number"]),
])
def test_collect_refuses_attributes_outside_their_vocabulary_or_range(attrs, words):
    """Issues 45.1 and 45.6: a run's attributes reach the summary, its tables and the report, so a
    value outside its vocabulary, a non-integer seed or a non-finite coordinate is refused, naming it."""
    with pytest.raises(ValueError) as refused:
        collect_analyses([_analysis(**attrs)])
    assert all(word in str(refused.value) for word in words), str(refused.value)
    assert collect_analyses([_analysis()]).attrs["rolling_lever"] == "paper"


def test_a_count_of_one_takes_the_singular():
    """Issue 79.9: "1 packing", "mean of 1 seed", never "1 packings" or "1 seeds"."""
    assert counted(1, "seed") == "1 seed"
    assert counted(0, "packing") == "0 packings"
    assert counted(3, "seed") == "3 seeds"
    assert counted(1, "seed", 3) == "1-3 seeds"
    assert counted(2, "collapse", 2) == "2 collapses"
