"""CPUs this process may use, and how many torch threads the PPO update uses.

torch's OpenMP threads spin-wait for each other. On an idle 2-core machine two update threads
are ~1.3x faster than one on the Baoding network; when another process holds a core, a
descheduled thread stalls every op and the same update runs 10-100x slower
(``experiments/RESULTS.md``, "Shared machine"). So the update runs on all the CPUs this process
may use while no other process is using them, and on one thread while others are (measured
from the kernel's CPU time counters, not from our own timings, which vary with the minibatch's
layout). On a quiet machine the choice never changes, so runs stay bit-reproducible; torch
splits some sums by thread count, so a run that had to make room for other processes is
reproducible only statistically.

``GOMP_SPINCOUNT`` (how long an idle OpenMP thread spins before it sleeps) is lowered from
libgomp's 300,000 to 10,000 before torch loads: the same speed on a quiet machine, a far
smaller stall in the moments before other processes are noticed.

Processes at idle priority (``SCHED_IDLE``, ``train.py --background``) count as others too:
beside one, two update threads ran the live chain at 0.15x its speed (each barrier's wake-up
let it in), one thread at 0.95x (``experiments/RESULTS.md``, "A second run at idle priority").
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path

CGROUP_ROOT = Path("/sys/fs/cgroup")


def _cgroup_cpu_limit(root: Path = CGROUP_ROOT, proc_cgroup: Path = Path("/proc/self/cgroup")) -> float | None:
    """CPUs allowed by this process's cgroup quota (v2 ``cpu.max`` or v1 CFS), None if unlimited."""
    candidates: list[Path] = []
    try:
        for line in proc_cgroup.read_text().splitlines():
            hierarchy, controllers, path = line.split(":", 2)
            if hierarchy == "0" or "cpu" in controllers.split(","):
                candidates.append(path.lstrip("/"))
    except (OSError, ValueError):
        pass
    limits = []
    for relative in [*candidates, ""]:
        v2 = root / relative / "cpu.max"
        v1_quota, v1_period = root / "cpu" / relative / "cpu.cfs_quota_us", root / "cpu" / relative / "cpu.cfs_period_us"
        try:
            if v2.is_file():
                quota, period = v2.read_text().split()[:2]
                if quota != "max":
                    limits.append(int(quota) / int(period))
            elif v1_quota.is_file():
                quota = int(v1_quota.read_text())
                if quota > 0:
                    limits.append(quota / int(v1_period.read_text()))
        except (OSError, ValueError):
            continue
    return min(limits) if limits else None


def available_cpus() -> int:
    """CPUs this process may actually use: its affinity mask, capped by a cgroup CPU quota and by
    ``OMP_NUM_THREADS`` when set (Ray sets it to an actor's ``num_cpus``), never below 1."""
    try:
        count = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        count = os.cpu_count() or 1
    limit = _cgroup_cpu_limit()
    if limit is not None:
        count = min(count, max(1, math.ceil(limit)))
    omp = os.environ.get("OMP_NUM_THREADS", "")
    if omp.isdigit() and int(omp) > 0:
        count = min(count, int(omp))
    return max(1, count)


# libgomp's spin count, lowered: threads spin-waiting for a core another process holds make an
# update 10-100x slower. Set before torch loads (myo_sds.set_process_environment).
OPENMP_SPIN = {"GOMP_SPINCOUNT": "10000"}


def _clock_ticks_per_second() -> float:
    try:
        return float(os.sysconf("SC_CLK_TCK"))
    except (AttributeError, ValueError, OSError):
        return 100.0


class CpuContention:
    """How many of this process's CPUs other processes have kept busy since the last reading.

    Reads the busy time of the CPUs in the process's affinity mask (``/proc/stat``) and the
    process's own CPU time; the difference is what others used. Where ``/proc/stat`` is not
    readable (not Linux), it reports 0: no contention seen.
    """

    def __init__(self, stat_path: Path = Path("/proc/stat"), clock: Callable[[], float] = time.monotonic,
                 own_cpu_seconds: Callable[[], float] | None = None) -> None:
        self.stat_path, self.clock = stat_path, clock
        self.own_cpu_seconds = own_cpu_seconds or (lambda: sum(os.times()[:2]))
        try:
            self.cpus = {f"cpu{index}" for index in os.sched_getaffinity(0)}
        except AttributeError:
            self.cpus = set()
        self.tick = _clock_ticks_per_second()
        self._last = self._read()

    def _busy_seconds(self) -> float | None:
        try:
            lines = self.stat_path.read_text().splitlines()
        except OSError:
            return None
        busy = 0.0
        for line in lines:
            name, *fields = line.split()
            if name.startswith("cpu") and name != "cpu" and (not self.cpus or name in self.cpus):
                values = [int(v) for v in fields[:8]]  # user nice system idle iowait irq softirq steal
                busy += sum(values) - values[3] - values[4]
        return busy / self.tick

    def _read(self) -> tuple[float, float | None, float]:
        return self.clock(), self._busy_seconds(), self.own_cpu_seconds()

    def others_cpus(self) -> float:
        """CPUs' worth of time other processes used since the last call (0 when unknown)."""
        now = self._read()
        (then_wall, then_busy, then_own), self._last = self._last, now
        elapsed = now[0] - then_wall
        if then_busy is None or now[1] is None or elapsed <= 0:
            return 0.0
        return max(0.0, (now[1] - then_busy) - (now[2] - then_own)) / elapsed


def run_at_idle_priority() -> None:
    """Put this process, and every thread it starts from now on, in Linux's idle scheduling class:
    it runs only on CPU time other processes leave (``train.py --background``)."""
    if not hasattr(os, "SCHED_IDLE"):
        raise OSError("--background needs Linux's SCHED_IDLE scheduling class; on this system use `nice -n 19`")
    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))


class UpdateThreads:
    """The torch thread count for the next minibatches of a PPO update.

    All ``cpus`` while other processes use less than ``busy_above`` CPUs on average, one
    thread from then until they use less than ``quiet_below`` (a gap, so that a load near the
    line does not flip the choice every reading). Contention is read at most every
    ``recheck_s`` seconds.

    Args:
        cpus: the CPUs this process may use (:func:`available_cpus`).
        fixed: a thread count set by the user (``num_threads`` in the run config), or None.
        contention: the reader of other processes' CPU use.
    """

    def __init__(self, cpus: int, fixed: int | None = None, contention: CpuContention | None = None,
                 busy_above: float = 0.5, quiet_below: float = 0.25, recheck_s: float = 0.5,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.home = fixed or cpus
        self.adaptive = fixed is None and cpus > 1
        self.contention = contention if contention is not None else (CpuContention() if self.adaptive else None)
        self.busy_above, self.quiet_below, self.recheck_s = busy_above, quiet_below, recheck_s
        self.clock = clock
        self.current = self.home
        self.checked_at = -math.inf
        self.switches = 0

    def threads(self) -> int:
        """The thread count to use now (re-reads contention when ``recheck_s`` has passed)."""
        if not self.adaptive or self.clock() - self.checked_at < self.recheck_s:
            return self.current
        self.checked_at = self.clock()
        others = self.contention.others_cpus()
        wanted = self.current
        if self.current == self.home and others > self.busy_above:
            wanted = 1
        elif self.current != self.home and others < self.quiet_below:
            wanted = self.home
        if wanted != self.current:
            self.current, self.switches = wanted, self.switches + 1
        return self.current
