"""A normalizing flow as emcee's independence proposal, against the default t-mixture.

Run (pinned to one core; ≈ 15 min on a busy machine)::

    taskset -c 1 python benchmarks/posterior_flow.py [--max-steps 6000] [--log data/synthetic/csf8_paper.csv]

Needs ``flowjax`` (``pip install flowjax>=19``; benchmark only, not a dependency of hdid).

Issue 17 proposed preconditioning emcee with a normalizing flow fitted to burn-in draws.
This script plugs one into :func:`hdid.sample_posterior` through its ``moves=`` factory:
a rational-quadratic-spline coupling flow (flowjax; 4 layers, width 48, 8 knots) is fitted
by maximum likelihood to the whitened walker positions of the burn-in stages (its
``burn_in_update`` hook; at most 4000 draws), with a 10 % defensive share of the adapted
t-mixture so that the importance ratio stays bounded, and used as an exact independence
Metropolis–Hastings proposal (50 % of the moves; DE 40 %, snooker 10 %). Then the same log
with the default moves. Both runs: adaptive chain up to ``--max-steps``, arviz criterion.

The committed result (``benchmarks/results/posterior_flow.md``) was measured with the same
proposal built into ``sample_posterior`` (fitted after the burn-in, run 200 steps, refitted
once to all draws, then fixed) before it was taken out of the library; this script is the
out-of-library equivalent for re-measuring.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"

#: Share of the proposal drawn from the t-mixture (defensive importance sampling).
DEFENSIVE = 0.1
#: Flow size: coupling layers, hidden width, spline knots, spline interval (whitened units).
FLOW_LAYERS = 4
FLOW_WIDTH = 48
FLOW_KNOTS = 8
FLOW_INTERVAL = 6.0
#: Training: Adam learning rate, epochs cap, early-stopping patience, batch size, and
#: the most draws trained on (a random subset of the burn-in: its cost, not the
#: proposal's quality, grows with more of these correlated draws).
LEARNING_RATE = 3e-3
MAX_EPOCHS = 100
PATIENCE = 8
BATCH_SIZE = 256
MAX_TRAIN = 4000


class FlowProposal:
    """Independence proposal ``(1 − ε)·flow + ε·mixture``; call as an emcee MH proposal."""

    def __init__(self, X, mixture, *, seed: int = 0, defensive: float = DEFENSIVE):
        import equinox as eqx
        import jax
        import jax.numpy as jnp
        from flowjax.bijections import RationalQuadraticSpline
        from flowjax.distributions import Normal
        from flowjax.flows import coupling_flow
        from flowjax.train import fit_to_data

        X = np.asarray(X, dtype=float)
        X = X[np.all(np.isfinite(X), axis=1)]
        if X.shape[0] > MAX_TRAIN:
            X = X[np.random.default_rng(seed).choice(X.shape[0], MAX_TRAIN, replace=False)]
        D = X.shape[1]
        self.mean = X.mean(axis=0)
        C = np.cov(X, rowvar=False) + 1e-12 * np.eye(D) * max(np.trace(np.cov(X, rowvar=False)) / D, 1e-300)
        self.L = np.linalg.cholesky(C)
        self.Linv = np.linalg.inv(self.L)
        self.logdet = float(np.sum(np.log(np.diag(self.L))))
        Z = (X - self.mean) @ self.Linv.T
        key = jax.random.key(seed)
        k1, k2 = jax.random.split(key)
        flow = coupling_flow(k1, base_dist=Normal(jnp.zeros(D)),
                             transformer=RationalQuadraticSpline(knots=FLOW_KNOTS, interval=FLOW_INTERVAL),
                             flow_layers=FLOW_LAYERS, nn_width=FLOW_WIDTH)
        self.flow, losses = fit_to_data(k2, flow, jnp.asarray(Z), learning_rate=LEARNING_RATE,
                                        max_epochs=MAX_EPOCHS, max_patience=PATIENCE,
                                        batch_size=BATCH_SIZE, show_progress=False)
        self.epochs = len(losses["train"])
        self.val_loss = float(losses["val"][-1])
        self._sample = eqx.filter_jit(lambda f, k, n: f.sample(k, (n,)))
        self._logp = eqx.filter_jit(lambda f, z: f.log_prob(z))
        self.mixture = mixture
        self.defensive = float(defensive)

    def logpdf(self, X) -> np.ndarray:
        import jax.numpy as jnp

        X = np.atleast_2d(X)
        Z = (X - self.mean) @ self.Linv.T
        lf = np.asarray(self._logp(self.flow, jnp.asarray(Z)), dtype=float) - self.logdet
        lf = np.where(np.isfinite(lf), lf, -np.inf)
        if self.defensive <= 0:
            return lf
        lm = self.mixture.logpdf(X)
        a, b = math.log1p(-self.defensive) + lf, math.log(self.defensive) + lm
        top = np.maximum(a, b)
        return top + np.log(np.exp(a - top) + np.exp(b - top))

    def sample(self, n: int, random) -> np.ndarray:
        import jax

        key = jax.random.key(int(random.randint(0, 2**31 - 1)))
        Z = np.asarray(self._sample(self.flow, key, n), dtype=float)
        X = self.mean + Z @ self.L.T
        if self.defensive > 0:
            pick = random.uniform(size=n) < self.defensive
            if pick.any():
                X[pick] = self.mixture.sample(int(pick.sum()), random)
        return X

    def __call__(self, coords, random):
        new = self.sample(coords.shape[0], random)
        return new, self.logpdf(coords) - self.logpdf(new)


def flow_moves_factory(lp, proposal):
    """``moves=`` factory: DE + snooker + an independence move whose proposal is the
    adapted t-mixture until the flow is fitted at the end of the burn-in stages."""
    import emcee

    class FlowMove(emcee.moves.MHMove):
        def __init__(self):
            self.flow, self.draws, self.fit_s = None, [], 0.0
            super().__init__(self._propose)

        def _propose(self, coords, random):
            return (proposal if self.flow is None else self.flow)(coords, random)

        def burn_in_update(self, rate, draws):
            self.draws.append(np.asarray(draws))
            if len(self.draws) >= 2:  # fit on the last two stages' draws
                t = time.perf_counter()
                self.flow = FlowProposal(np.concatenate(self.draws[-2:]), proposal.mix,
                                         seed=len(self.draws))
                self.fit_s += time.perf_counter() - t

    move = FlowMove()
    flow_moves_factory.last = move
    return [(emcee.moves.DEMove(), 0.4), (emcee.moves.DESnookerMove(), 0.1), (move, 0.5)]


def main(argv=None):
    import hdid

    ap = argparse.ArgumentParser()
    ap.add_argument("--log", type=Path, default=ROOT / "data" / "synthetic" / "csf8_paper.csv")
    ap.add_argument("--max-steps", type=int, default=6000)
    ap.add_argument("--out-dir", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    fit = hdid.fit(args.log)
    rows = {}
    for name, moves in (("flow", flow_moves_factory), ("mixture (default)", None)):
        la0 = [round(x, 2) for x in os.getloadavg()]
        t = time.perf_counter()
        post = hdid.sample_posterior(fit, seed=0, max_steps=args.max_steps, moves=moves)
        d = post.to_dict()["posterior_diagnostics"]
        rows[name] = {"wall_s": time.perf_counter() - t, "load": [la0, [round(x, 2) for x in os.getloadavg()]],
                      "steps": d["n_steps"], "converged": d["converged"],
                      "rhat_max": d["convergence"]["rhat_max"],
                      "ess_bulk_min": d["convergence"]["ess_bulk_min"],
                      "move_acceptance": d["move_acceptance"], "stage_s": d["stage_s"],
                      "flow_fit_s": getattr(getattr(flow_moves_factory, "last", None), "fit_s", None)
                      if moves else None}
        print(name, rows[name], flush=True)
    (args.out_dir / "posterior_flow_rerun.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    sys.exit(main())
