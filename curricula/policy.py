"""RecurrentPPO's LSTM policy with a whole-sequence LSTM pass during updates.

sb3-contrib runs the LSTM one time step at a time in Python whenever a sequence of a
minibatch contains an episode start (sb3-contrib issue #113), which is almost always, since
its rollout buffer cuts sequences at episode starts. A start can then only be a sequence's
first step: resetting those sequences' initial states and running the LSTM once over the whole
sequence computes the same function, several times faster. Anything else falls back to the
step-by-step loop.
"""

from __future__ import annotations

import torch as th
from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy


class SequenceLstmPolicy(RecurrentActorCriticPolicy):
    """``MlpLstmPolicy`` (same networks, same parameters) with the whole-sequence fast path."""

    @staticmethod
    def _process_sequence(features: th.Tensor, lstm_states: tuple[th.Tensor, th.Tensor],
                          episode_starts: th.Tensor, lstm: th.nn.LSTM) -> tuple[th.Tensor, th.Tensor]:
        n_seq = lstm_states[0].shape[1]
        starts = episode_starts.reshape((n_seq, -1)).swapaxes(0, 1)  # (length, n_seq)
        if not th.all(starts[1:] == 0.0):
            return RecurrentActorCriticPolicy._process_sequence(features, lstm_states, episode_starts, lstm)
        features_sequence = features.reshape((n_seq, -1, lstm.input_size)).swapaxes(0, 1)
        keep = (1.0 - starts[0]).view(1, n_seq, 1)
        output, lstm_states = lstm(features_sequence, (keep * lstm_states[0], keep * lstm_states[1]))
        return th.flatten(output.transpose(0, 1), start_dim=0, end_dim=1), lstm_states
