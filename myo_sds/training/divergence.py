"""An update that leaves the policy non-finite: undone, and the run stopped with the reason."""

from __future__ import annotations


class UpdateDiverged(RuntimeError):
    """A PPO update left non-finite parameters (the model is restored to before it)."""


def finite(model) -> bool:
    return all(bool(p.isfinite().all()) for p in model.policy.parameters())


def training_state(model) -> tuple[dict, dict]:
    """Copies of the policy's weights and the optimizer's state, to undo an update."""
    import copy

    return ({k: v.detach().clone() for k, v in model.policy.state_dict().items()},
            copy.deepcopy(model.policy.optimizer.state_dict()))


def restore_training_state(model, saved: tuple[dict, dict]) -> None:
    weights, optimizer = saved
    model.policy.load_state_dict(weights)
    model.policy.optimizer.load_state_dict(optimizer)
