"""How far a Baoding policy turns the balls, step by step: where a stage stalls without drops.

One deterministic episode on our env. Every ``--every`` steps it prints the turn of the targets
and of the balls (the world-frame angle of the pair vector 1 - 2, unwrapped from the start, in
degrees), the lag between them, solved steps so far, and the finger joints that turn the balls,
so that a policy which stops turning (e.g. a finger at its joint limit) shows where and why.

    python experiments/orbit_track.py models/baoding_p1_2022 --env p1_2022
    python experiments/orbit_track.py ~/runs/RUN --load-checkpoint 2000000 --episode-steps 400
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import math

import numpy as np

from myo_sds.evaluation.checkpoints import choose_env, load_policy, resolve_checkpoint
from myo_sds.evaluation.episodes import make_env

FINGER_JOINTS = ("mcp2_flexion", "cmc_abduction", "mp_flexion", "ip_flexion")


def pair_angle(positions: np.ndarray) -> float:
    dx, dy = positions[0, :2] - positions[1, :2]
    return math.atan2(dy, dx)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policy", help="a model folder, run folder or checkpoint .zip")
    parser.add_argument("--env", default="p1_2022", help="a preset (p1, p1_2022, p2) or stage:NAME")
    parser.add_argument("--load-checkpoint", type=int, default=None, metavar="STEPS")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episode-steps", type=int, default=None, help="control steps (default: the task's 200)")
    parser.add_argument("--every", type=int, default=10, help="print every this many steps")
    args = parser.parse_args()

    ref = resolve_checkpoint(args.policy, args.load_checkpoint)
    choice = choose_env(ref, args.env)
    policy = load_policy(ref, choice.task)
    env = make_env(choice)
    if args.episode_steps is not None:
        env.configure(episode_steps=args.episode_steps)
    base = env.unwrapped
    joints = {name: base.model.jnt_qposadr[base.model.joint(name).id] for name in FINGER_JOINTS}

    obs, _ = env.reset(seed=args.seed)
    state, start = None, True
    turns = {"targets": [], "balls": []}
    solved = step = 0
    print(f"{'step':>4} {'targets':>8} {'balls':>8} {'lag':>6} {'solved':>6}  "
          + " ".join(f"{name:>13}" for name in FINGER_JOINTS))
    while True:
        action, state = policy.act(obs, state, start)
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        step += 1
        solved += int(bool(info["solved"]))
        for key, sites in (("targets", base._target_sites), ("balls", base._ball_sites)):
            angle = pair_angle(base.data.site_xpos[list(sites)])
            previous = turns[key][-1] if turns[key] else angle
            turns[key].append(previous + (angle - previous + math.pi) % (2 * math.pi) - math.pi)
        if step % args.every == 0 or terminated or truncated:
            target, ball = (math.degrees(turns[k][-1] - turns[k][0]) for k in ("targets", "balls"))
            print(f"{step:>4} {target:>8.0f} {ball:>8.0f} {target - ball:>6.0f} {solved:>6}  "
                  + " ".join(f"{base.data.qpos[address]:>13.2f}" for address in joints.values()))
        if terminated or truncated:
            break
    result = info["episode_result"]
    print(f"score {result.score:.3f} over {result.horizon} steps, {'dropped' if result.dropped else 'no drop'}")


if __name__ == "__main__":
    main()
