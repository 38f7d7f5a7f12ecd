"""Lattice exploration: noise in the policy's latent state, so the action noise is correlated
across muscles and depends on the state (Chiappa et al., "Latent Exploration for Reinforcement
Learning", NeurIPS 2023).

With ``x`` the actor's latent features (its LSTM output here; no gradient flows from the noise
into them), ``W, b`` the action layer and two noise matrices drawn from zero-mean Gaussians,
``P_x`` (d x d, latent) and ``P_a`` (d x A, action), the action is

    a = W (x + alpha * x P_x) + b + x P_a,

Given ``x`` the action is Gaussian with mean ``W x + b`` and covariance

    Sigma = alpha^2 W diag(v) W^T + diag(u),   v_j = sum_i x_i^2 s_ij^2,   u_k = sum_i x_i^2 t_ik^2 + reg^2 + eps,

``s`` and ``t`` the standard deviations of the entries of ``P_x`` and ``P_a`` (``eps`` = 1e-6 keeps
Sigma invertible where the latent is all zeros). The policy's
log-probability and entropy are those of this multivariate normal. The matrices are redrawn
every ``noise_resample_every`` control steps of a rollout (RecurrentPPO's ``sde_sample_freq``),
one pair per env.

The standard deviations come from the learned ``log_std`` (d x 2 by default: one value per latent
feature for ``P_x``'s row and one for ``P_a``'s; d x (d + A) with ``full_std``), clipped to
``std_clip``, scaled by ``1 / sqrt(d)`` so the noise does not grow with the latent size, and
mapped through ``exp`` or, with ``use_expln``, gSDE's ``expln`` (exp below 0, log1p + 1 above).
"""

from __future__ import annotations

import math

import torch as th
from stable_baselines3.common.distributions import StateDependentNoiseDistribution
from torch import nn

LOG_2PI = math.log(2 * math.pi)


class _InverseAndHalfLogDet(th.autograd.Function):
    """``(Sigma^-1, 0.5 log det Sigma)`` of a batch of covariance matrices from one Cholesky
    factor, with the closed-form gradients (d Sigma^-1 = -Sigma^-1 dSigma Sigma^-1, d 0.5 log det =
    0.5 Sigma^-1): the same values and gradients as differentiating through the factor, without
    its backward pass of batched triangular solves (most of a Lattice minibatch's time)."""

    @staticmethod
    def forward(ctx, sigma: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        factor = th.linalg.cholesky(sigma)
        inverse = th.cholesky_inverse(factor)
        ctx.save_for_backward(inverse)
        return inverse, factor.diagonal(dim1=-2, dim2=-1).log().sum(-1)

    @staticmethod
    def backward(ctx, grad_inverse: th.Tensor, grad_half_logdet: th.Tensor) -> th.Tensor:
        (inverse,) = ctx.saved_tensors
        grad = 0.5 * grad_half_logdet[..., None, None] * inverse
        if grad_inverse is not None:
            grad = grad - inverse @ grad_inverse @ inverse
        return grad


class MultivariateGaussian:
    """N(mean, covariance_matrix) for a batch: the log-probability and entropy Lattice's loss
    needs (as ``torch.distributions.MultivariateNormal``'s), from one Cholesky factor per sample."""

    def __init__(self, mean: th.Tensor, covariance_matrix: th.Tensor) -> None:
        self.mean, self.covariance_matrix = mean, covariance_matrix
        self._inverse, self._half_logdet = _InverseAndHalfLogDet.apply(covariance_matrix)

    def log_prob(self, value: th.Tensor) -> th.Tensor:
        diff = value - self.mean
        mahalanobis = (diff.unsqueeze(-2) @ self._inverse @ diff.unsqueeze(-1))[..., 0, 0]
        return -0.5 * (mahalanobis + self.mean.shape[-1] * LOG_2PI) - self._half_logdet

    def entropy(self) -> th.Tensor:
        return 0.5 * self.mean.shape[-1] * (1.0 + LOG_2PI) + self._half_logdet


class LatticeNoise(StateDependentNoiseDistribution):
    """The Lattice action distribution, wired into SB3 as a state-dependent noise distribution
    (the policy draws its matrices through ``reset_noise``, as for gSDE)."""

    def __init__(self, action_dim: int, full_std: bool = False, use_expln: bool = True, alpha: float = 1.0,
                 std_clip: tuple[float, float] = (1e-3, 10.0), std_reg: float = 0.0, epsilon: float = 1e-6,
                 min_action_std: float | None = None):
        super().__init__(action_dim, full_std=full_std, use_expln=use_expln, squash_output=False,
                         learn_features=False, epsilon=epsilon)
        self.alpha, self.std_reg = alpha, std_reg
        # A floor on each muscle's independent noise (policy.log_std_min): u_k >= min_action_std^2,
        # so each muscle's whole std is at least that (the latent part only adds to it).
        self.min_action_variance = None if min_action_std is None else min_action_std**2
        self.min_std, self.max_std = std_clip
        self.mean_actions_net: nn.Linear | None = None

    def get_std(self, log_std: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """The standard deviations of the entries of ``P_x`` (d x d) and ``P_a`` (d x A)."""
        d = self.latent_sde_dim
        log_std = log_std.clip(min=math.log(self.min_std), max=math.log(self.max_std)) - 0.5 * math.log(d)
        if self.use_expln:
            below = th.exp(log_std) * (log_std <= 0)
            above = (th.log1p(log_std * (log_std > 0) + self.epsilon) + 1.0) * (log_std > 0)
            std = below + above
        else:
            std = th.exp(log_std)
        if self.full_std:
            return std[:, :d], std[:, d:]
        ones = th.ones(d, d + self.action_dim, device=log_std.device)
        return ones[:, :d] * std[:, :1], ones[:, d:] * std[:, 1:]

    def sample_weights(self, log_std: th.Tensor, batch_size: int = 1) -> None:
        """Draw the noise matrices: one pair, and ``batch_size`` pairs for parallel envs."""
        latent_std, action_std = self.get_std(log_std)
        self._drawn_action_std = action_std.detach()  # what the drawn P_a's entries spread by (the floor's check)
        self.latent_weights = th.distributions.Normal(th.zeros_like(latent_std), latent_std)
        self.action_weights = th.distributions.Normal(th.zeros_like(action_std), action_std)
        self.latent_mat, self.action_mat = self.latent_weights.rsample(), self.action_weights.rsample()
        self.latent_matrices = self.latent_weights.rsample((batch_size,))
        self.action_matrices = self.action_weights.rsample((batch_size,))

    def proba_distribution_net(self, latent_dim: int, log_std_init: float = 0.0,
                               latent_sde_dim: int | None = None) -> tuple[nn.Module, nn.Parameter]:
        self.mean_actions_net = nn.Linear(latent_dim, self.action_dim)
        self.latent_sde_dim = latent_dim if latent_sde_dim is None else latent_sde_dim
        columns = self.latent_sde_dim + self.action_dim if self.full_std else 2
        log_std = nn.Parameter(th.ones(self.latent_sde_dim, columns) * log_std_init, requires_grad=True)
        self.sample_weights(log_std)
        return self.mean_actions_net, log_std

    def covariance(self, log_std: th.Tensor, latent: th.Tensor) -> th.Tensor:
        """Sigma for each row of ``latent`` (batch x A x A)."""
        latent_std, action_std = self.get_std(log_std)
        squared = latent.detach() ** 2
        latent_variance = squared @ latent_std**2  # batch x d
        # epsilon, as gSDE adds it: a latent of zeros (a dead ReLU layer) gives no noise at all
        action_variance = squared @ action_std**2 + self.std_reg**2 + self.epsilon  # batch x A
        if self.min_action_variance is not None:
            action_variance = action_variance.clamp(min=self.min_action_variance)
        weight = self.mean_actions_net.weight  # A x d
        if self.full_std:
            sigma = self.alpha**2 * (weight * latent_variance[:, None, :]) @ weight.T
        else:  # every latent feature's noise has the same variance: Sigma = alpha^2 v W W^T + diag(u)
            sigma = self.alpha**2 * latent_variance[:, :1, None] * (weight @ weight.T)
        return sigma + th.diag_embed(action_variance)

    def proba_distribution(self, mean_actions: th.Tensor, log_std: th.Tensor, latent_sde: th.Tensor) -> LatticeNoise:
        self._latent = latent_sde.detach()
        self.distribution = MultivariateGaussian(mean_actions, self.covariance(log_std, latent_sde))
        return self

    def log_prob(self, actions: th.Tensor) -> th.Tensor:
        return self.distribution.log_prob(actions)

    def entropy(self) -> th.Tensor:
        return self.distribution.entropy()

    def _noise(self, latent: th.Tensor, single: th.Tensor, per_env: th.Tensor) -> th.Tensor:
        if len(latent) == 1 or len(latent) != len(per_env):
            return latent @ single
        return th.bmm(latent.unsqueeze(1), per_env).squeeze(1)

    def sample(self) -> th.Tensor:
        latent = self._latent
        latent_noise = self._noise(latent, self.latent_mat, self.latent_matrices)
        action_noise = self._noise(latent, self.action_mat, self.action_matrices)
        if self.min_action_variance is not None:  # the floor's share of the independent part
            drawn = (latent.detach() ** 2) @ self._drawn_action_std**2 + self.std_reg**2 + self.epsilon
            extra = (self.min_action_variance - drawn).clamp(min=0.0)
            action_noise = action_noise + extra.sqrt() * th.randn_like(action_noise)
        return self.distribution.mean + self.alpha * latent_noise @ self.mean_actions_net.weight.T + action_noise

    def mode(self) -> th.Tensor:
        return self.distribution.mean
