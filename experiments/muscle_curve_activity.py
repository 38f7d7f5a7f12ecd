"""How much MuJoCo 2.1.0's muscle length curve (`muscle_curve: "2.1.0"`) acts in a policy's episodes.

Plays a policy on a stage env of its run's curriculum that has the knob on and counts the physics
substeps in which 2.1.0's extra force is not zero (a muscle shortened below its ``lmin``), with the
largest single muscle force and the mean summed force when it acts, beside the muscles' own summed
force.

    python experiments/muscle_curve_activity.py RUN/checkpoints/rl_model_N_steps.zip stage:rotate-25s --episodes 6
"""

from __future__ import annotations

import argparse

import numpy as np

from myo_sds import evaluation as ev
from myo_sds.envs import muscle_2022


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint", help="a checkpoint .zip inside a run folder whose stage has the knob on")
    parser.add_argument("env", help="stage:NAME of the run's curriculum")
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--start-noise", type=float, default=0.02)
    args = parser.parse_args()

    counts = {"substeps": 0, "active": 0}
    largest, summed, muscles = [0.0], [], []
    original = muscle_2022.MuscleCurve2022.actuator_force

    def recorded(self, data):
        force = original(self, data)
        counts["substeps"] += 1
        muscles.append(float(np.abs(data.actuator_force[self.muscles]).sum()))
        if force.any():
            counts["active"] += 1
            largest[0] = max(largest[0], float(np.abs(force).max()))
            summed.append(float(np.abs(force).sum()))
        return force

    muscle_2022.MuscleCurve2022.actuator_force = recorded
    ref = ev.resolve_checkpoint(args.checkpoint)
    ev.evaluate(ref, ev.choose_env(ref, args.env, start_noise=args.start_noise), episodes=args.episodes, seed=0)
    if not counts["substeps"]:
        parser.error(f"{args.env} of this run does not have muscle_curve: \"2.1.0\": nothing was measured")
    share = 100 * counts["active"] / counts["substeps"]
    print(f"{args.env}, {args.episodes} episodes: {counts['substeps']} substeps, extra force in {counts['active']} "
          f"({share:.1f}%); largest {largest[0]:.1f} N on one muscle; summed when acting: mean "
          f"{np.mean(summed) if summed else 0.0:.1f} N, against {np.mean(muscles):.1f} N summed over the muscles' "
          f"own forces (mean per substep)")


if __name__ == "__main__":
    main()
