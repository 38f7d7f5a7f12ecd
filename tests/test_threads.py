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
    contention = CpuContention(stat, clock=clock, own_cpu_seconds=lambda: own[0], proc_path=tmp_path / "no-proc")
    # Over 2 s: our CPUs were busy 3 s in all (cpu2 is not ours), 1 s of it ours.
    clock.now, own[0] = 2.0, 1.0
    write(200, 100, 1000)
    assert contention.others_cpus() == pytest.approx(1.0)
    # Nothing readable: no contention seen.
    stat.unlink()
    assert contention.others_cpus() == 0.0


def _write_proc_stat(proc, pid: int, name: str, policy: int, utime: int, stime: int) -> None:
    """A /proc/<pid>/stat line: fields 3.. after the name; utime 14, stime 15, policy 41."""
    fields = ["S"] + ["0"] * 49
    fields[11], fields[12], fields[38] = str(utime), str(stime), str(policy)
    (proc / str(pid)).mkdir(parents=True, exist_ok=True)
    (proc / str(pid) / "stat").write_text(f"{pid} ({name}) {' '.join(fields)}\n")


def test_processes_at_idle_priority_are_not_contention(monkeypatch, tmp_path):
    monkeypatch.setattr(threads.os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(threads, "_clock_ticks_per_second", lambda: 100.0)
    stat, proc = tmp_path / "stat", tmp_path / "proc"
    stat.write_text("cpu0 0 0 0 0 0 0 0 0\ncpu1 0 0 0 0 0 0 0 0\n")
    _write_proc_stat(proc, 41, "python train.py", threads.SCHED_IDLE, 1000, 50)  # a --background run
    _write_proc_stat(proc, 42, "make", 0, 7, 3)  # an ordinary process
    (proc / "self").mkdir()  # not a pid: skipped
    clock, own = FakeClock(), [0.0]
    contention = CpuContention(stat, clock=clock, own_cpu_seconds=lambda: own[0], proc_path=proc, idle_rescan_s=10.0)
    # Over 2 s: our CPUs busy 3.5 s, 0.5 s ours, 1.6 s the background run's (its 2 s and
    # 200 + 40 ticks less what it had), 1.4 s the ordinary process's.
    clock.now, own[0] = 2.0, 0.5
    stat.write_text("cpu0 200 0 0 0 0 0 0 0\ncpu1 0 0 150 0 0 0 0 0\n")
    _write_proc_stat(proc, 41, "python train.py", threads.SCHED_IDLE, 1120, 90)
    _write_proc_stat(proc, 42, "make", 0, 147, 3)
    assert contention.others_cpus() == pytest.approx((3.5 - 0.5 - 1.6) / 2.0)
    # A background run that ends between readings takes its time with it: nothing is subtracted.
    (proc / "41" / "stat").unlink()
    clock.now = 3.0
    stat.write_text("cpu0 300 0 0 0 0 0 0 0\ncpu1 0 0 150 0 0 0 0 0\n")
    assert contention.others_cpus() == pytest.approx(1.0)


@pytest.mark.skipif(not hasattr(threads.os, "SCHED_IDLE"), reason="Linux scheduling classes")
def test_the_kernel_reports_a_background_process_at_idle_priority(tmp_path):
    """``run_at_idle_priority`` (``train.py --background``) puts a process in the idle class, and
    the real /proc shows its CPU time there; an ordinary process's is not taken for it."""
    import subprocess
    import sys
    import time

    busy = ("import sys, time\nfrom myo_sds.threads import run_at_idle_priority\n"
            "if sys.argv[1] == 'idle': run_at_idle_priority()\n"
            "print('ready', flush=True)\nend = time.time() + 6\nwhile time.time() < end: pass\n")
    seen = {}  # kind -> whether the reader took the child for idle-class, and its CPU seconds there
    for kind in ("idle", "ordinary"):
        child = subprocess.Popen([sys.executable, "-c", busy, kind], stdout=subprocess.PIPE, text=True)
        try:
            assert child.stdout.readline().strip() == "ready"
            reader = threads.IdleClassCpu(threads.Path("/proc"), threads._clock_ticks_per_second(), time.monotonic, 0.0)
            reader.seconds_since_last()
            first = reader._ticks.get(child.pid)
            deadline = time.monotonic() + 4.0
            while time.monotonic() < deadline:  # a busy machine leaves it less
                time.sleep(0.5)
                reader.seconds_since_last()
                if first is None or (reader._ticks.get(child.pid, first) - first) / reader.tick >= 0.2:
                    break
            last = reader._ticks.get(child.pid)
            seen[kind] = (last is not None, 0.0 if last is None else (last - first) / reader.tick)
        finally:
            child.kill()
            child.wait()
    assert seen["idle"][0] and seen["idle"][1] >= 0.2
    assert seen["ordinary"] == (False, 0.0)


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
