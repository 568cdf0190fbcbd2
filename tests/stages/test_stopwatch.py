"""The stopwatch of a run over its segments (colsim.stages.stopwatch): it starts from what earlier
segments took, and an unknown CPU time stays unknown. Bounds from the clocks being monotonic, not
from how fast this machine is."""
import math
import time

from colsim.stages import stopwatch
from colsim.stages.stopwatch import Stopwatch


def test_a_resumed_stopwatch_counts_on_from_the_earlier_segments():
    clock = Stopwatch(wall=100.0, cpu=40.0)
    cpu_before = time.process_time()
    while time.process_time() - cpu_before < 0.02:   # spend some CPU in this process
        sum(range(1000))
    assert clock.wall() >= 100.0 and clock.cpu() >= 40.02 - 1e-9


def test_a_fresh_stopwatch_starts_at_zero_and_an_unknown_cpu_time_stays_unknown():
    fresh = Stopwatch()
    assert 0.0 <= fresh.wall() and 0.0 <= fresh.cpu()
    assert math.isnan(Stopwatch(wall=5.0, cpu=float("nan")).cpu())


def test_a_checkpoint_is_due_at_its_step_or_after_the_interval(monkeypatch):
    clock = Stopwatch()
    monkeypatch.setattr(stopwatch, "CHECKPOINT_INTERVAL_S", 1e9)
    assert clock.checkpoint_due(True) and not clock.checkpoint_due(False)
    monkeypatch.setattr(stopwatch, "CHECKPOINT_INTERVAL_S", 0.0)   # any wall time since the last is enough
    assert clock.checkpoint_due(False)
