"""colsim.study.workflow.job_resources: a job's cluster resources and priority, from its settings."""
from __future__ import annotations

import pytest

from colsim.study.workflow.job_resources import (ANALYSIS_PRIORITY, PACK_PRIORITY, PACK_REFERENCE_S,
                                                 PACK_REFERENCE_SPHERES, SETTINGS_PRIORITY, collapse_priority,
                                                 collapse_runtime, pack_priority, pack_resources, spheres_of)
from test_study_plan import study_config
from colsim.study.workflow.plan import StudyPlan


def test_a_runs_time_limit_and_priority_come_from_its_settings():
    plan = StudyPlan(study_config())
    length = plan.length
    assert collapse_runtime(plan.run_settings(0.12, 100, 4.0, "associated"), length) == 120
    assert collapse_runtime(plan.run_settings(0.12, 200, 4.0, "associated"), length) == 300
    assert collapse_runtime(plan.run_settings(0.12, 100, 8.0, "associated"), length) == 300
    assert collapse_runtime(plan.run_settings(0.12, 100, 4.0, "coulomb"), length) == 1440
    assert collapse_priority(0.5, plan.run_settings(0, 100, 4.0, "associated"), length) == 5
    assert collapse_priority(2.0, plan.run_settings(0, 200, 4.0, "associated"), length) == 40


def test_settings_then_the_largest_pours_then_collapses_run_first():
    """The scheduler's order: a settings file before the job it gates, pours before collapses (a
    column's collapses wait for its pour anyway, and a long pour left for last would run alone),
    the r0 = 6 pour before the r0 = 5 one, and an analysis before any collapse (seconds, and its
    run's numbers readable at once)."""
    plan = StudyPlan(study_config())
    r5, r6 = (pack_priority(spheres_of(r0, 5 * r0, (0.25, 0.5))) for r0 in (5, 6))
    longest_collapse = collapse_priority(5.0, plan.run_settings(0.12, 2 * plan.length[0], 4.0, "associated"),
                                         plan.length)
    assert SETTINGS_PRIORITY > r6 > r5 > PACK_PRIORITY > ANALYSIS_PRIORITY > longest_collapse


def test_a_big_columns_jobs_ask_for_time_and_memory_by_its_size():
    """Up to the measured r0 = 4 the limits are the flat ones; above, they grow with the spheres:
    a pour twice the reference's spheres gets 4x twice its time (N^2, slower cores), a collapse of
    twice the spheres 2^1.43 its base; nothing asks for more than 48 hours."""
    plan = StudyPlan(study_config())
    run, length = plan.run_settings(0.12, 100, 4.0, "associated"), plan.length
    assert spheres_of(4, 20, (0.25, 0.5)) == pytest.approx(PACK_REFERENCE_SPHERES, rel=0.01)
    assert pack_resources(3_000) == {"runtime": 120, "mem_mb": 4000}
    doubled = pack_resources(2 * PACK_REFERENCE_SPHERES)
    assert doubled["runtime"] == pytest.approx(2 * 4 * PACK_REFERENCE_S / 60, abs=1)
    assert doubled["mem_mb"] == pytest.approx(2 * 2 * 1_561 * PACK_REFERENCE_SPHERES / 22_330, abs=1)
    assert pack_resources(1e7)["runtime"] == 2880
    assert collapse_runtime(run, length, 10_000) == 120
    assert collapse_runtime(run, length, 2 * 20_400) == pytest.approx(120 * 2**1.43, abs=1)
    assert collapse_runtime(plan.run_settings(0.12, 100, 4.0, "coulomb"), length, 1e7) == 2880


def test_a_job_asks_for_a_gpu_on_cuda_and_on_auto_for_a_large_column_where_one_is(monkeypatch, tmp_path):
    from colsim.solvers.defaults import GPU_FROM_SPHERES
    from colsim.study.workflow import job_resources

    assert job_resources.gpus_a_job("cuda", 10) == 1 and job_resources.gpus_a_job("cpu", 10**7) == 0
    monkeypatch.setattr(job_resources, "NVIDIA_CONTROL", tmp_path / "nvidiactl")   # no GPU
    assert job_resources.gpus_a_job("auto", 10**7) == 0
    (tmp_path / "nvidiactl").touch()                                            # a GPU
    assert job_resources.gpus_a_job("auto", GPU_FROM_SPHERES) == 1
    assert job_resources.gpus_a_job("auto", GPU_FROM_SPHERES - 1) == 0
