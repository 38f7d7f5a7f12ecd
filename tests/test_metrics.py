"""Official metric functions against hand-computed values."""

import math

import pytest

from myo_sds.envs.metrics import (
    EpisodeResult,
    drop_rate,
    mean_confidence_interval,
    mean_effort,
    official_score,
)


def test_official_score_counts_steps_lost_to_a_drop_as_unsolved():
    full = EpisodeResult(solved_steps=150, length=200, horizon=200, dropped=False, effort=0.2)
    dropped = EpisodeResult(solved_steps=40, length=50, horizon=200, dropped=True, effort=0.4)
    assert full.score == 0.75 and dropped.score == 0.2  # 40 / 200, not 40 / 50
    assert official_score([full, dropped]) == pytest.approx(0.475)
    assert mean_effort([full, dropped]) == pytest.approx(0.3)
    assert drop_rate([full, dropped]) == 0.5
    assert math.isnan(official_score([]))


def test_confidence_interval():
    mean, low, high = mean_confidence_interval([0.0, 1.0, 0.0, 1.0])
    # std (ddof=1) = 0.57735; half width = 1.96 * 0.57735 / 2
    assert mean == 0.5 and high - mean == pytest.approx(0.565803, abs=1e-6) and low == pytest.approx(1 - high)
    assert mean_confidence_interval([0.3]) == (0.3, 0.3, 0.3)


def test_scores_by_start_phase_sector():
    from myo_sds.evaluation import per_start_phase

    def episode(degrees, solved, dropped=False, length=200):
        return EpisodeResult(solved, length, 200, dropped, 0.1, "hold", start_phase=math.radians(degrees))

    episodes = [episode(10, 100), episode(44.9, 50, True, 60), episode(183, 20, True, 35), episode(359.9, 200),
                EpisodeResult(10, 200, 200, False, 0.1, "hold", start_phase=2 * math.pi)]  # rounds up to 2 pi
    sectors = per_start_phase(episodes)
    assert list(sectors) == ["0-45", "180-225", "315-360"]
    assert sectors["0-45"] == {"episodes": 2, "score": pytest.approx(0.375), "drop_rate": 0.5, "drop_step": 60.0}
    assert sectors["180-225"] == {"episodes": 1, "score": pytest.approx(0.1), "drop_rate": 1.0, "drop_step": 35.0}
    assert sectors["315-360"] == {"episodes": 2, "score": pytest.approx(0.525), "drop_rate": 0.0, "drop_step": None}
    # One start phase for all episodes (P1's fixed start), or none recorded: no breakdown.
    assert per_start_phase([episode(45, 10), episode(45, 20)]) == {}
    assert per_start_phase([EpisodeResult(10, 200, 200, False, 0.1)]) == {}


def test_the_status_table_says_when_each_sector_drops_the_balls():
    from myo_sds.evaluation.summary import RunSummary, StageSummary, format_summary

    sectors = {"0-45": {"episodes": 3, "score": 0.1, "drop_rate": 2 / 3, "drop_step": 61.4},
               "45-90": {"episodes": 2, "score": 0.7, "drop_rate": 0.0, "drop_step": None}}
    stage = StageSummary(1, "hold", "current", 1000, 10.0, 5, "score", 0.55, 500, 0.34, by_start_phase=sectors)
    text = format_summary(RunSummary("run", "running", 1000, 10.0, [stage]), now=0.0)
    rows = {line.split()[0]: line.split()[1:] for line in text.splitlines() if line.startswith("  ")}
    assert rows["degrees"] == ["0-45", "45-90"] and rows["dropped"] == ["67%", "0%"]
    assert rows["at"] == ["step", "61", "-"]  # the mean step of the drops, rounded; none dropped: "-"


def test_solved_fraction_by_target_phase_sums_over_episodes():
    from myo_sds.evaluation import per_target_phase

    def episode(steps, solved):
        return EpisodeResult(sum(solved), sum(steps), 200, False, 0.1, "ccw",
                             steps_by_target_phase=tuple(steps), solved_by_target_phase=tuple(solved))

    a = episode([25, 25, 25, 25, 25, 25, 25, 25], [25, 20, 0, 0, 5, 25, 25, 25])
    b = episode([0, 0, 10, 40, 0, 0, 0, 0], [0, 0, 10, 10, 0, 0, 0, 0])  # dropped after 50 steps
    sectors = per_target_phase([a, b, EpisodeResult(5, 10, 200, True, 0.1)])  # one without phases
    assert sectors["0-45"] == {"steps": 25, "solved_fraction": 1.0}
    assert sectors["90-135"] == {"steps": 35, "solved_fraction": pytest.approx(10 / 35)}
    assert sectors["135-180"] == {"steps": 65, "solved_fraction": pytest.approx(10 / 65)}
    assert len(sectors) == 8
    assert per_target_phase([EpisodeResult(5, 10, 200, True, 0.1)]) == {}


def test_update_sizes_read_the_newest_updates_and_let_a_resume_supersede_its_replayed_steps(tmp_path):
    from torch.utils.tensorboard import SummaryWriter

    from myo_sds.evaluation.update_sizes import recent_update_sizes

    def log(stamp, ks, kl_offset):
        scratch = tmp_path / f"w{stamp}"
        with SummaryWriter(str(scratch)) as writer:
            for k in ks:
                writer.add_scalar("train/approx_kl", kl_offset + k / 100, 2048 * k)
                writer.add_scalar("train/clip_fraction", k / 100, 2048 * k)
                writer.add_scalar("train/explained_variance", 0.5, 2048 * k)
                writer.add_scalar("train/learning_rate", 1e-4 * k, 2048 * k)
        (events,) = scratch.glob("events.out.tfevents.*")
        events.rename(tmp_path / "tb" / f"events.out.tfevents.{stamp}.host.1.0")

    (tmp_path / "tb").mkdir()
    log(1000, range(1, 11), 0.0)  # updates 1-10, then a crash after the checkpoint at update 6
    log(2000, range(6, 13), 1.0)  # the resume logs updates 6-12 again
    # Kept: KL 0.01-0.05 (updates 1-5, first file), 1.06-1.12 (6-12, second); 0.07-0.10 are gone.
    every = recent_update_sizes(tmp_path / "tb")
    assert (every.updates, every.first_step, every.last_step) == (12, 2048, 2048 * 12)
    assert every.approx_kl_median == pytest.approx((1.06 + 1.07) / 2)
    assert every.learning_rate == pytest.approx(12e-4)
    newest = recent_update_sizes(tmp_path / "tb", last=4)  # updates 9-12
    assert (newest.updates, newest.first_step) == (4, 2048 * 9)
    assert newest.approx_kl_median == pytest.approx(1.105) and newest.approx_kl_p90 == pytest.approx(1.117)
    assert newest.clip_fraction_median == pytest.approx(0.105) and newest.explained_variance_median == 0.5
    assert newest.describe().startswith("the last 4 updates (18,432-24,576 env steps): approx KL median 1.105 "
                                        "(90th percentile 1.117), clip fraction 0.11, explained variance 0.50")
    assert recent_update_sizes(tmp_path / "missing") is None
