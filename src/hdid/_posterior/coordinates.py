"""Friction in data coordinates: the sampler's coordinates for the Stribeck + viscous law.

One job: a bijection between the friction law's ``(tau_c, c_v)`` and the friction torque
at two of the log's own sliding speeds, its inverse and ``log|det|`` of its Jacobian.

The sliding friction magnitude is ``F(ω) = tau_c·(1 − e(ω)) + tau_s·e(ω) + c_v·ω`` with
``e(ω) = exp(−(ω/v_s)^delta)``. For given ``(tau_s, v_s, delta)`` it is affine in
``(tau_c, c_v)``, so the torques ``F(ω₁), F(ω₂)`` at two fixed speeds determine them
by a 2 × 2 solve (Cramer). The walkers move in ``z_i = F(ω_i) / F_fit(ω_i)`` (1 at the
least-squares optimum) in place of ``tau_c`` and ``c_v``; every other coordinate is the
one :class:`~hdid._posterior.density.LogPosterior` samples anyway. The density carries
``log|∂u/∂s|`` so the target in the fit's parameters (likelihood × priors) is exactly
the one sampled without this map: only the coordinates change.

The speeds are fixed before sampling, from the least-squares fit's own trajectory (the
fraction-of-time quantiles ``SPEED_QUANTILES`` of ``|ω|`` over the sliding samples):
the data fix the friction torque where the log spends its time sliding, and a law that
trades ``tau_c`` against ``c_v`` (the Coulomb-limit ridge) keeps those torques.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

#: Quantiles of the fit's sliding speeds ``|ω|`` (over samples, i.e. time) at which the
#: friction torque is sampled (benchmarks/README.md, issue 17, branch ``post6``).
SPEED_QUANTILES = (0.25, 0.75)
#: Names of the friction law's parameters the map needs free and log-transformed
#: (``delta`` free and interval-transformed).
NAMES = ("tau_c", "c_v", "tau_s", "v_s", "delta")


class FrictionCoordinates(eqx.Module):
    """``(tau_c, c_v)`` ↔ ``z = F(speeds) / scale`` at fixed ``(tau_s, v_s, delta)``."""

    idx: tuple[int, int, int, int, int] = eqx.field(static=True)  # tau_c, c_v, tau_s, v_s, delta
    delta_interval: tuple[float, float] = eqx.field(static=True)
    speeds: jax.Array  # (2,) [rad/s], ascending
    scale: jax.Array  # (2,) F at the speeds at the least-squares optimum [N m]

    # -- the law -------------------------------------------------------------------------
    def _shape(self, u, xp):
        """``(tau_s, e(ω₁), e(ω₂))`` from the unknowns ``u`` (last axis)."""
        _, _, i_s, i_v, i_d = self.idx
        lo, hi = self.delta_interval
        tau_s = xp.exp(u[..., i_s])
        v_s = xp.exp(u[..., i_v])
        delta = lo + (hi - lo) / (1.0 + xp.exp(-u[..., i_d]))
        w = xp.asarray(self.speeds) if xp is np else self.speeds
        e = xp.exp(-((w / v_s[..., None]) ** delta[..., None]))
        return tau_s, e

    def forward(self, u, xp=jnp):
        """``z`` ``(..., 2)`` of unknowns ``u`` ``(..., n)``."""
        i_c, i_cv = self.idx[:2]
        tau_s, e = self._shape(u, xp)
        w = xp.asarray(self.speeds) if xp is np else self.speeds
        sc = xp.asarray(self.scale) if xp is np else self.scale
        F = (xp.exp(u[..., i_c])[..., None] * (1.0 - e) + tau_s[..., None] * e
             + xp.exp(u[..., i_cv])[..., None] * w)
        return F / sc

    def inverse(self, z, u, xp=jnp):
        """``(log tau_c, log c_v, log|∂(log tau_c, log c_v)/∂z|, valid)`` from ``z``
        ``(..., 2)`` and the other unknowns in ``u`` (``tau_s``, ``v_s``, ``delta``);
        ``valid`` is False where the solve gives ``tau_c ≤ 0`` or ``c_v ≤ 0`` (outside the
        law's domain: zero density) or is singular."""
        tau_s, e = self._shape(u, xp)
        w = xp.asarray(self.speeds) if xp is np else self.speeds
        sc = xp.asarray(self.scale) if xp is np else self.scale
        r = z * sc - tau_s[..., None] * e  # tau_c·(1 − e_i) + c_v·ω_i
        a1, a2 = 1.0 - e[..., 0], 1.0 - e[..., 1]
        det = a1 * w[1] - a2 * w[0]
        ok = det != 0
        sdet = xp.where(ok, det, 1.0)
        tau_c = (r[..., 0] * w[1] - r[..., 1] * w[0]) / sdet
        c_v = (a1 * r[..., 1] - a2 * r[..., 0]) / sdet
        valid = ok & (tau_c > 0) & (c_v > 0)
        tc = xp.where(valid, tau_c, 1.0)
        cv = xp.where(valid, c_v, 1.0)
        log_jac = (-xp.log(tc) - xp.log(cv) - xp.log(xp.abs(sdet))
                   + xp.log(sc[0]) + xp.log(sc[1]))
        return xp.log(tc), xp.log(cv), log_jac, valid


def friction_coordinates(fit, quantiles=SPEED_QUANTILES) -> FrictionCoordinates | None:
    """The map for ``fit``'s problem, speeds from the fit's own sliding trajectory;
    ``None`` if its model has not all of :data:`NAMES` free with the transforms the map
    assumes, or the log has fewer than two distinct sliding speeds."""
    prob = fit.problem
    free = list(prob.free)
    if not all(n in free for n in NAMES):
        return None
    specs = prob.base.parameter_specs()
    if any(specs[n].transform != "log" for n in NAMES[:4]):
        return None
    t = specs["delta"].transform
    if not (isinstance(t, tuple) and t[0] == "interval"):
        return None
    speeds = sliding_speeds(fit)
    if speeds.size < 2:
        return None
    w = np.quantile(speeds, quantiles)
    if not (w[1] > w[0] > 0):
        return None
    idx = tuple(free.index(n) for n in NAMES)
    fc = FrictionCoordinates(idx=idx, delta_interval=(float(t[1]), float(t[2])),
                             speeds=jnp.asarray(w), scale=jnp.ones(2))
    u = np.asarray(fit.u, dtype=float)
    scale = fc.forward(u, np)
    if not np.all(np.isfinite(scale) & (scale > 0)):
        return None
    return FrictionCoordinates(idx=idx, delta_interval=fc.delta_interval,
                               speeds=jnp.asarray(w), scale=jnp.asarray(scale))


def sliding_speeds(fit) -> np.ndarray:
    """``|ω|`` of the least-squares fit's trajectory at every logged sample where it
    slides (not stuck, speed above zero), all runs pooled."""
    prob = fit.problem
    _, omega, stuck = map(np.asarray, prob.simulate(np.asarray(fit.u), prob.times,
                                                    full_output=True))
    w = np.asarray(prob.weight)
    out = []
    for i in range(omega.shape[0]):
        m = (~stuck[i]) & (np.abs(omega[i]) > 0) & (w[i] > 0)
        out.append(np.abs(omega[i][m]))
    return np.concatenate(out) if out else np.zeros(0)
