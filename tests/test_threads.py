"""CPU budget and the update's thread choice: the rule without a clock, the numbers it relies on."""

from __future__ import annotations

import pytest

from myo_sds import threads
from myo_sds.threads import CpuContention, UpdateThreads, available_cpus


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class FakeContention:
    def __init__(self) -> None:
        self.others = 0.0
        self.readings = 0

    def others_cpus(self) -> float:
        self.readings += 1
        return self.others


def test_update_uses_all_cpus_until_other_processes_need_them():
    clock, contention = FakeClock(), FakeContention()
    threads = UpdateThreads(cpus=2, contention=contention, busy_above=0.5, quiet_below=0.25, recheck_s=0.5,
                            clock=clock)

    def choices(others: float, seconds: float) -> list[int]:
        contention.others, seen = others, []
        for _ in range(round(seconds / 0.1)):
            clock.now += 0.1
            seen.append(threads.threads())
        return seen

    assert set(choices(0.05, 10)) == {2}  # a quiet machine: never a change, so runs stay reproducible
    assert choices(1.0, 0.6)[-1] == 1  # another process takes a core: one thread from the next reading on
    assert set(choices(0.4, 5)) == {1}  # between the lines: no flip-flopping
    assert choices(0.1, 0.6)[-1] == 2 and threads.switches == 2
    assert contention.readings <= 172 // 5 + 1  # at most one reading every 0.5 s


def test_a_fixed_thread_count_is_never_changed():
    contention = FakeContention()
    contention.others = 2.0
    threads = UpdateThreads(cpus=2, fixed=2, contention=contention)
    assert {threads.threads() for _ in range(10)} == {2} and contention.readings == 0


def test_contention_is_the_busy_time_of_our_cpus_less_our_own(monkeypatch, tmp_path):
    monkeypatch.setattr(threads.os, "sched_getaffinity", lambda pid: {0, 1})
    stat = tmp_path / "stat"

    def write(cpu0_busy: int, cpu1_busy: int, cpu2_busy: int) -> None:
        # user nice system idle iowait irq softirq steal, in clock ticks (100 per second here)
        stat.write_text(f"cpu  0 0 0 0 0 0 0 0\ncpu0 {cpu0_busy} 0 0 500 9 0 0 0\n"
                        f"cpu1 0 0 {cpu1_busy} 700 0 0 0 0\ncpu2 {cpu2_busy} 0 0 0 0 0 0 0\nintr 5\n")

    clock, own = FakeClock(), [0.0]
    monkeypatch.setattr(threads, "_clock_ticks_per_second", lambda: 100.0)
    write(0, 0, 0)
    contention = CpuContention(stat, clock=clock, own_cpu_seconds=lambda: own[0])
    # Over 2 s: our CPUs were busy 3 s in all (cpu2 is not ours), 1 s of it ours.
    clock.now, own[0] = 2.0, 1.0
    write(200, 100, 1000)
    assert contention.others_cpus() == pytest.approx(1.0)
    # Nothing readable: no contention seen.
    stat.unlink()
    assert contention.others_cpus() == 0.0


def test_available_cpus_follows_affinity_quota_and_omp_num_threads(monkeypatch, tmp_path):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setattr(threads.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    monkeypatch.setattr(threads, "_cgroup_cpu_limit", lambda: None)
    assert available_cpus() == 4
    monkeypatch.setattr(threads, "_cgroup_cpu_limit", lambda: 1.5)  # a quota of 1.5 CPUs
    assert available_cpus() == 2
    monkeypatch.setenv("OMP_NUM_THREADS", "1")  # what Ray sets for an actor with num_cpus=1
    assert available_cpus() == 1


@pytest.mark.parametrize("content,expected", [("max 100000\n", None), ("150000 100000\n", 1.5)])
def test_cgroup_v2_quota_is_read(tmp_path, content, expected):
    (tmp_path / "job").mkdir()
    (tmp_path / "job" / "cpu.max").write_text(content)
    proc = tmp_path / "cgroup"
    proc.write_text("0::/job\n")
    assert threads._cgroup_cpu_limit(root=tmp_path, proc_cgroup=proc) == expected


def test_one_and_two_threads_give_bit_identical_lstm_outputs():
    """A policy acts the same whatever the thread count: the LSTM over a rollout, and the heads
    one time step at a time (as a policy acts, 8 envs per step), split no sums by thread. Larger
    products may: on an Intel Xeon with the AVX2 pins the heads over all 512 rows at once differ
    in the last bit, and on an AMD EPYC the LSTM weights' gradients do, which is why a run whose
    update had to change thread counts is reproducible only statistically (myo_sds/threads.py)."""
    import torch

    def outputs(count: int) -> tuple[torch.Tensor, torch.Tensor]:
        previous = torch.get_num_threads()
        torch.set_num_threads(count)
        try:
            torch.manual_seed(0)
            lstm = torch.nn.LSTM(86, 64)
            head = torch.nn.Sequential(torch.nn.Linear(64, 64), torch.nn.ReLU(), torch.nn.Linear(64, 39))
            with torch.no_grad():
                output, _ = lstm(torch.randn(64, 8, 86))
                return output, torch.stack([head(step) for step in output])
        finally:
            torch.set_num_threads(previous)

    assert all(torch.equal(a, b) for a, b in zip(outputs(1), outputs(2)))


@pytest.mark.skipif(not hasattr(threads.os, "SCHED_IDLE"), reason="Linux scheduling classes")
def test_train_background_runs_at_idle_priority(tmp_path):
    import subprocess
    import sys

    script = ("import os\nfrom myo_sds.cli.train import main\n"
              "code = main(['--background', '--status', os.sys.argv[1]])\n"
              "print(code, os.sched_getscheduler(0) == os.SCHED_IDLE)\n")
    shown = subprocess.run([sys.executable, "-c", script, str(tmp_path / "no-run")], capture_output=True, text=True)
    assert shown.stdout.split() == ["2", "True"]  # no such run (exit 2), at idle priority all the same
