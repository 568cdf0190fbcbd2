"""colsim.study.workflow.commands: a run's command-line options and cluster resources, from its settings."""
from __future__ import annotations

from colsim.study.workflow.commands import collapse_options, collapse_priority, collapse_runtime, numbers
from test_study_plan import study_config
from colsim.study.workflow.plan import StudyPlan


def test_list_options_keep_every_digit():
    assert numbers([0.1, 0.5, 1.0]) == "0.1 0.5 1" and numbers([0.1308996938995747]) == "0.1308996938995747"


def test_a_runs_options_come_from_its_settings():
    plan = StudyPlan(study_config())
    run = plan.run_settings(0.12, 100, 4.0, "associated")
    assert collapse_options(run) == ("--rolling-lever paper --friction-law associated --steps 100 --duration 4"
                                     " --frame-every 10 --solver auto")
    coulomb = plan.run_settings(0.12, 100, 4.0, "coulomb")
    assert collapse_options(coulomb).startswith("--rolling-lever paper --friction-law coulomb --steps 100")
    assert "--friction-tolerance 1e-05 --solver auto" in collapse_options(coulomb)
    rest = StudyPlan(study_config({"collapse": {"max_duration": 8, "rest_tolerance": 0.2},
                                   "solver_overlap_tolerance": 0}))
    options = collapse_options(rest.run_settings(0.12, 100, 4.0, "associated"))
    assert options.endswith("--max-duration 8 --rest-window 1 --rest-tolerance 0.2 --rest-energy 0.01"
                            " --solver auto --solver-overlap-tolerance 0")


def test_a_runs_time_limit_and_priority_come_from_its_settings():
    plan = StudyPlan(study_config())
    length = plan.length
    assert collapse_runtime(plan.run_settings(0.12, 100, 4.0, "associated"), length) == 120
    assert collapse_runtime(plan.run_settings(0.12, 200, 4.0, "associated"), length) == 300
    assert collapse_runtime(plan.run_settings(0.12, 100, 8.0, "associated"), length) == 300
    assert collapse_runtime(plan.run_settings(0.12, 100, 4.0, "coulomb"), length) == 1440
    assert collapse_priority(0.5, plan.run_settings(0, 100, 4.0, "associated"), length) == 5
    assert collapse_priority(2.0, plan.run_settings(0, 200, 4.0, "associated"), length) == 40
