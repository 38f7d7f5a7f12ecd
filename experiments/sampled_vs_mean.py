"""The same checkpoint's episodes with the mean action (as every evaluation plays them) and with
actions sampled from the policy (as training plays them), on one env, same seeds.

    python experiments/sampled_vs_mean.py RUN_OR_CHECKPOINT --env stage:rotate-20s --episodes 40

Where training episodes return more than the stage evaluation, this says whether the policy's own
noise is what carries them (the evaluation's env and seeds, only the action choice differs).
"""

from __future__ import annotations

import argparse
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from myo_sds import set_process_environment


def main() -> None:
    set_process_environment()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("target")
    parser.add_argument("--env", default="stage:rotate-20s")
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--start-noise", type=float, default=0.0)
    args = parser.parse_args()
    import torch

    from myo_sds import evaluation as ev
    from myo_sds.envs.metrics import drop_rate
    from myo_sds.evaluation.checkpoints import LoadedPolicy, load_policy
    from myo_sds.evaluation.episodes import make_env, run_episodes_together

    ref = ev.resolve_checkpoint(args.target)
    choice = ev.choose_env(ref, args.env, start_noise=args.start_noise)
    policy = load_policy(ref, choice.task)
    seeds = list(range(args.episodes))
    envs = [make_env(choice) for _ in seeds]
    original = LoadedPolicy.act_together

    def sampled(self, batch, state, episode_starts):
        if self.normalizer is not None:
            batch = self.normalizer.normalize_obs(batch)
        return self.model.predict(batch, state=state, episode_start=episode_starts, deterministic=False)

    print(f"{ref.model} on {choice.label}, {args.episodes} episodes (seeds 0..)")
    with ThreadPoolExecutor(2) as pool:
        for name, act in (("mean action", original), ("sampled", sampled)):
            torch.manual_seed(0)
            LoadedPolicy.act_together = act
            results = run_episodes_together(policy, envs, choice, seeds, pool)
            groups = [("all", results)] + [(d, [r for r in results if r.direction == d]) for d in ("hold", "cw", "ccw")]
            groups += [(s, [r for r in results if r.start == s]) for s in ("on_targets", "rest")]
            for label, group in groups:
                if group:
                    print(f"  {name:12s} {label:10s} n={len(group):3d} return {np.mean([r.reward for r in group]):7.1f}"
                          f"  score {np.mean([r.score for r in group]):.3f}  dropped {drop_rate(group):.0%}"
                          f"  median solved {np.median([r.solved_steps for r in group]):.0f}")
    LoadedPolicy.act_together = original


if __name__ == "__main__":
    main()
