"""colsim.study.workflow.checks without Snakemake: each check returns one line naming the culprit, or None."""
from __future__ import annotations

import math

from colsim.study.workflow.checks import (before_validation, cross_field_problem, load_schema, non_finite_number,
                                          schema_problem, size_problem)
from helpers import ROOT
from test_study_plan import study_config

SCHEMA = load_schema(ROOT / "workflow" / "schemas" / "config.schema.yaml")


def test_the_schema_names_an_unknown_key_and_a_wrong_value():
    assert schema_problem({"r0": 1}, SCHEMA) is None
    assert schema_problem({"collapse": {"stepz": 5}}, SCHEMA).startswith(
        "config: unknown key collapse.stepz; allowed in collapse: threads, duration, steps")
    assert schema_problem({"solver": "simplex"}, SCHEMA).startswith("config: solver: 'simplex' is not one of")


def test_a_configuration_too_large_once_expanded_is_refused_before_the_schema():
    layer = [1] * 10
    for _ in range(5):
        layer = [layer] * 10   # 10^6 leaves, shared as YAML's aliases share them
    assert size_problem({"a": layer}).startswith("config: more than 100,000 keys and values")
    assert size_problem({"r0": 1}) is None
    assert before_validation({"a": layer}, SCHEMA).startswith("config: more than")
    assert before_validation({"bogus": 1}, SCHEMA).startswith("config: unknown key bogus")


def test_a_nan_or_an_infinity_is_named_by_its_key():
    assert non_finite_number({"mu_r": [0.1, math.nan]}) == "mu_r.1"
    assert non_finite_number({"collapse": {"max_duration": math.inf}}) == "collapse.max_duration"
    assert non_finite_number({"r0": 1, "study": "x"}) is None


def test_settings_that_contradict_each_other():
    assert cross_field_problem(study_config()) is None
    assert cross_field_problem(study_config({"r0": 0.2})) == (
        "config: r0 0.2 is below diameter_max 0.5: the largest particle does not fit in the cylinder")
    assert cross_field_problem(study_config({"friction_law": "coulomb", "friction_law_comparison": True})
                               ).startswith("config: friction_law_comparison needs friction_law: associated")
    assert cross_field_problem(study_config({"r0": 1000})).startswith("config: a packing of r0 1000 for a = 1")
