"""Where a run is in its curriculum: one object, saved with every checkpoint
(``curriculum_state.json``), changed only through its methods by the trainer; the run folder
reads and writes it, the advancement rule (:func:`myo_sds.curricula.advancement.decide`) reads it.
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Protocol


class LoggedEpisode(Protocol):
    step: int
    wall_s: float


class RunStatus(str, enum.Enum):
    """Where a run stands; the first three can be resumed (budget_reached with a larger budget)."""

    RUNNING = "running"
    INTERRUPTED = "interrupted"  # Ctrl-C or SIGTERM
    TIME_LIMIT = "time_limit"  # --max-hours
    BUDGET_REACHED = "budget_reached"  # total_steps spent
    COMPLETED = "completed"  # the last stage passed
    STOPPED = "stopped"  # a stage ran out of steps with on_max_steps: stop
    DIVERGED = "diverged"  # an update made the policy non-finite; the run kept the policy from before it


@dataclass(frozen=True)
class Transition:
    """A stage's end: passed, timed out (and the run went on) or stopped the run."""

    stage: str
    stage_index: int
    decision: str  # an advancement Decision's value: passed | timed_out | plateaued | stop
    at_step: int  # the run's env step count when it happened
    stage_steps: int
    stage_episodes: int
    measured: float  # the advancement metric over the stage's window
    # The run's training wall time then (None in states written before it was kept). Not part of
    # equality: two runs with the same schedule differ in timing.
    wall_s: float | None = field(default=None, compare=False)
    # With a stage evaluation: its best mean score, and the step of the policy handed to the next
    # stage (that of the best evaluation with ``hand_off: best``; None: the stage's last policy).
    best_evaluated: float | None = None
    handed_off_step: int | None = None
    # The best evaluation's mean return (its reward weights), and the stage-end probe of the
    # policy handed on (``probe`` in the curriculum): its env, score, median solved steps, drop rate.
    best_evaluated_reward: float | None = None
    probe: dict | None = None


@dataclass
class CurriculumState:
    """Where the run is in its curriculum; saved with every checkpoint."""

    stage_index: int = 0
    stage_start_step: int = 0
    stage_episodes: int = 0
    recent: list[float] = field(default_factory=list)  # the advancement window's values
    episodes_per_stage: dict[str, int] = field(default_factory=dict)
    steps_per_stage: dict[str, int] = field(default_factory=dict)
    history: list[Transition] = field(default_factory=list)
    status: RunStatus = RunStatus.RUNNING
    num_timesteps: int = 0
    wall_s: float = 0.0  # training wall time so far, over all sessions of the run
    # The current stage's best full-window mean, counting only rises of the plateau gain, and
    # the stage step it was reached at (None: not tracked, or no full window yet).
    best_measured: float | None = None
    best_at_stage_step: int = 0
    # The current stage's periodic evaluations (``evaluate`` in the curriculum): how many ran,
    # the last and the best one's mean score and mean return, and the run's env step of the best
    # (the best by the stage's ``select``: score or reward).
    evaluations: int = 0
    last_evaluated: float | None = None
    best_evaluated: float | None = None
    best_evaluated_step: int | None = None
    last_evaluated_reward: float | None = None
    best_evaluated_reward: float | None = None

    # the current stage ------------------------------------------------------------------

    @property
    def stage_steps(self) -> int:
        """Env steps spent in the current stage."""
        return self.num_timesteps - self.stage_start_step

    @property
    def measured(self) -> float:
        """The advancement metric: the mean of the window's values (nan before the first episode)."""
        return sum(self.recent) / len(self.recent) if self.recent else math.nan

    def record(self, stage: str, num_timesteps: int, values: Iterable[float] = (), window: int | None = None,
               plateau_gain: float | None = None) -> None:
        """The current stage ``stage`` is at env step ``num_timesteps``: add the metric values of
        the episodes that ended since, keeping the last ``window``; with ``plateau_gain``, a
        full window's mean at least that much above the best so far becomes the best."""
        self.num_timesteps = num_timesteps
        for value in values:
            self.recent.append(float(value))
            self.stage_episodes += 1
        if window is not None:
            del self.recent[:-window]
            full = len(self.recent) >= window
            if plateau_gain is not None and full and (
                    self.best_measured is None or self.measured >= self.best_measured + plateau_gain):
                self.best_measured, self.best_at_stage_step = self.measured, self.stage_steps
        self.episodes_per_stage[stage] = self.stage_episodes
        self.steps_per_stage[stage] = self.stage_steps

    def record_evaluation(self, score: float, reward: float | None = None, select: str = "score") -> bool:
        """A periodic evaluation of the current stage at the current step; True when it is the
        stage's best so far by ``select`` (score or reward; strictly above: the earliest of equal
        values is kept)."""
        self.evaluations += 1
        self.last_evaluated, self.last_evaluated_reward = score, reward
        if select == "reward":
            best = self.best_evaluated_reward is None or (reward is not None and reward > self.best_evaluated_reward)
        else:
            best = self.best_evaluated is None or score > self.best_evaluated
        if best:
            self.best_evaluated, self.best_evaluated_reward = score, reward
            self.best_evaluated_step = self.num_timesteps
        return best

    def end_stage(self, stage: str, decision: str, wall_s: float, handed_off_step: int | None = None,
                  probe: dict | None = None) -> Transition:
        """Record the current stage's end (``decision``: passed | timed_out | plateaued | stop), the
        step of the policy it hands on, when not its last, and the stage-end probe of that policy."""
        transition = Transition(stage, self.stage_index, decision, self.num_timesteps, self.stage_steps,
                                self.stage_episodes, self.measured, wall_s, self.best_evaluated, handed_off_step,
                                self.best_evaluated_reward, probe)
        self.history.append(transition)
        return transition

    def begin_next_stage(self) -> None:
        """Start the next stage at the current step, with an empty window."""
        self.stage_index += 1
        self.stage_start_step = self.num_timesteps
        self.stage_episodes = 0
        self.recent = []
        self.best_measured, self.best_at_stage_step = None, 0
        self.evaluations, self.last_evaluated, self.best_evaluated, self.best_evaluated_step = 0, None, None, None
        self.last_evaluated_reward = self.best_evaluated_reward = None

    def rewind_current_stage(self, step: int, episodes: Sequence[LoggedEpisode] = ()) -> None:
        """Describe the current stage as it stood at ``step`` (an earlier policy of it, e.g. its best
        evaluated one, exported): the step counts and, when the run's episode log reaches back to
        ``step`` (a log restarted by a resume may not), the stage's episodes and the training wall
        time. The advancement window is left as it is."""
        if not self.stage_start_step <= step <= self.num_timesteps:
            raise ValueError(f"step {step:,} is outside the current stage ({self.stage_start_step:,} to "
                             f"{self.num_timesteps:,})")
        logged = [e for e in episodes if e.step <= self.num_timesteps]
        if logged and logged[0].step <= step:
            self.stage_episodes -= sum(1 for e in logged if e.step > step)
            self.wall_s = [e.wall_s for e in logged if e.step <= step][-1]
        self.num_timesteps = step
        if self.steps_per_stage:
            stage = self.trained_stages()[-1]
            self.steps_per_stage[stage], self.episodes_per_stage[stage] = self.stage_steps, self.stage_episodes

    # the whole run -------------------------------------------------------------------

    def trained_stages(self) -> list[str]:
        """The stages the run has trained in so far, in order (the current one once it has steps)."""
        return list(self.steps_per_stage)

    def curriculum_mismatch(self, stage_names: Sequence[str]) -> str | None:
        """Why a curriculum with stages ``stage_names`` cannot continue this run, or None: the
        stages the run has trained in must keep their names and places; the stages after them
        may be added, removed or changed (e.g. the run's ``curriculum.yaml`` edited before a
        ``--resume``)."""
        trained = self.trained_stages()
        if len(stage_names) < len(trained):
            why = f"it has {len(stage_names)} stages, and the run has trained in {len(trained)} ({', '.join(trained)})"
        else:
            why = next((f"stage {index + 1} is {new!r} where the run trained in {old!r}"
                        for index, (new, old) in enumerate(zip(stage_names, trained)) if new != old), None)
        if why is None:
            return None
        return (f"{why}; the stages the run has trained in ({', '.join(trained)}) must stay as they were, in "
                f"that order; only the stages after {trained[-1]!r} may be added, removed or changed")

    def stage_starts(self) -> list[int]:
        """The env step at which each stage reached so far began."""
        return [0] + [t.at_step for t in self.history]

    def stage_start_walls(self, episodes: Sequence[LoggedEpisode]) -> list[float]:
        """The training wall time at which each stage reached so far began. Transitions
        written before they kept it take it from the last episode logged by then."""
        walls = [0.0]
        for transition in self.history:
            if transition.wall_s is not None:
                walls.append(transition.wall_s)
            else:
                logged = [e.wall_s for e in episodes if e.step <= transition.at_step]
                walls.append(logged[-1] if logged else walls[-1])
        return walls

    def to_json(self) -> str:
        values = asdict(self)
        values["status"] = self.status.value
        return json.dumps(values, indent=2)

    @classmethod
    def from_json(cls, text: str) -> CurriculumState:
        values = json.loads(text)
        values["status"] = RunStatus(values["status"])
        values["history"] = [Transition(**entry) for entry in values.get("history", [])]
        return cls(**values)


