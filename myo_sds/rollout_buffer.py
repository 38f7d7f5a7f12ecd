"""sb3-contrib's recurrent rollout buffer with its minibatch padding vectorized.

sb3-contrib pads each minibatch's sequences field by field, one tensor per sequence and
``pad_sequence`` (nine fields, ~30 sequences per minibatch of 128 in the 2022 phase-1 recipe):
16% of the recipe's PPO update. :class:`PaddedRolloutBuffer` computes the same padded layout
once per minibatch, as one index array, and gathers every field through it: the same samples,
value for value (tests/test_speed_parts.py), at a fraction of the cost.

With ``max_sequence_length`` (``ppo.sequence_length``) it also cuts every sequence after that many
steps: each piece starts from the LSTM state the rollout stored at its first step, so the
forward pass computes the same values and only the gradient is truncated there. A minibatch is
padded to its longest sequence, so where episodes differ in length (a die dropped after 20 steps
beside one held for 150) the cut removes most of the padding.
"""

from __future__ import annotations

import numpy as np
from sb3_contrib.common.recurrent.buffers import RecurrentRolloutBuffer
from sb3_contrib.common.recurrent.type_aliases import RecurrentRolloutBufferSamples, RNNStates


def padded_layout(episode_starts: np.ndarray, env_change: np.ndarray,
                  max_length: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each step of a minibatch goes when its sequences (cut at episode starts and env
    changes, as sb3-contrib cuts them, and every ``max_length`` steps if given) are padded to the
    longest: the sequences' first steps, an (n_seq, max_length) array of step indices, and which
    of its entries are real steps."""
    starts = np.logical_or(episode_starts, env_change).flatten()
    starts[0] = True
    if max_length is not None:
        first = np.flatnonzero(starts)
        position = np.arange(len(starts)) - first[np.cumsum(starts) - 1]  # steps since the sequence began
        starts |= position % max_length == 0
    first = np.flatnonzero(starts)
    lengths = np.diff(np.append(first, len(starts)))
    offsets = np.arange(lengths.max())
    real = offsets[None, :] < lengths[:, None]
    return first, np.where(real, first[:, None] + offsets[None, :], 0), real


class PaddedRolloutBuffer(RecurrentRolloutBuffer):
    """:class:`RecurrentRolloutBuffer` whose minibatches are padded in one gather per field."""

    max_sequence_length: int | None = None  # set by the trainer (ppo.sequence_length)

    def _get_samples(self, batch_inds: np.ndarray, env_change: np.ndarray, env=None) -> RecurrentRolloutBufferSamples:
        first, index, real = padded_layout(self.episode_starts[batch_inds], env_change[batch_inds],
                                           self.max_sequence_length)
        self.seq_start_indices = first
        rows = batch_inds[index]  # buffer rows of every padded step (row 0 where padding)
        mask = real.astype(np.float32)

        def padded(field: np.ndarray):
            values = field[rows]
            return self.to_torch(values * mask.reshape(mask.shape + (1,) * (values.ndim - 2)))

        def flat(field: np.ndarray):
            return padded(field).flatten()

        n = index.size
        starts = batch_inds[first]
        states = [self.to_torch(field[starts].swapaxes(0, 1)).contiguous()
                  for field in (self.hidden_states_pi, self.cell_states_pi, self.hidden_states_vf, self.cell_states_vf)]
        return RecurrentRolloutBufferSamples(
            observations=padded(self.observations).reshape((n, *self.obs_shape)),
            actions=padded(self.actions).reshape((n, *self.actions.shape[1:])),
            old_values=flat(self.values),
            old_log_prob=flat(self.log_probs),
            advantages=flat(self.advantages),
            returns=flat(self.returns),
            lstm_states=RNNStates((states[0], states[1]), (states[2], states[3])),
            episode_starts=flat(self.episode_starts),
            mask=self.to_torch(mask).flatten(),
        )
