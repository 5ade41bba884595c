"""A posterior on disk: :meth:`PosteriorResult.save` and :meth:`PosteriorResult.load`.

One arviz NetCDF file. Its ``posterior`` group is what arviz readers expect (every
physical and derived quantity, walkers as chains: ``arviz.from_netcdf`` reads it as
before). A group ``hdid_raw`` keeps what a :class:`PosteriorResult` is made of beyond it:
the kept chain in the sampled space ``(steps, walkers, D)``, the thinned draws, each
quantity's draws, τ, the walkers' acceptance and the optima's unknowns and Laplace
covariances; its ``summary`` attribute holds the rest as JSON (diagnostics, warnings, the
basin check, the priors, the width ratios, the run times) and ``fit`` the fit's own JSON
(:meth:`hdid.FitResult.save`'s). A loaded result has the fit read back without its log
(``FitResult.load``: no ``predict``), unless the live fit is passed (``fit=``).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

#: Version of this layout (a newer one is refused with the fix).
SAVED_VERSION = 1
_GROUP = "hdid_raw"


def save(result, path) -> None:
    """Write ``result`` to ``path`` (arviz NetCDF, module docstring)."""
    import xarray as xr

    from .._results._saved import finite

    idata = result.to_inference_data()
    S, W, D = result.chain.shape
    modes = list(result.modes)
    data = {
        "chain": (("step", "walker", "dim"), np.asarray(result.chain, dtype=float)),
        "draws": (("draw", "dim"), np.asarray(result.draws, dtype=float)),
        # own dimensions: their lengths differ between engines (SMC: τ of ones, an
        # acceptance per SMC step)
        "tau": (("tau_i",), np.asarray(result.tau, dtype=float)),
        "acceptance": (("acceptance_i",), np.asarray(result.acceptance, dtype=float)),
    }
    if result.tau_emcee is not None:
        data["tau_emcee"] = (("tau_emcee_i",), np.asarray(result.tau_emcee, dtype=float))
    if result.mode_share is not None:
        data["mode_share"] = (("mode",), np.asarray(result.mode_share, dtype=float))
    if modes:
        data["mode_u"] = (("mode", "unknown"), np.array([m.u for m in modes], dtype=float))
        data["mode_cov"] = (("mode", "unknown", "unknown2"),
                            np.array([m.cov for m in modes], dtype=float))
    names = {}
    for group, values in (("samples", result.samples), ("derived", result.derived)):
        names[group] = list(values)
        for i, (n, v) in enumerate(values.items()):
            data[f"{group}_{i}"] = (("draw_q",), np.asarray(v, dtype=float))
    conv = result.convergence
    summary = {
        "saved_version": SAVED_VERSION, "names": names, "labels": list(result.labels),
        "burn": result.burn, "thin": result.thin, "warnings": list(result.warnings),
        "seed": result.seed, "wall_time_s": result.wall_time_s, "temper": result.temper,
        "residual_rho1": result.residual_rho1, "burn_in": result.burn_in,
        "mode_search_s": result.mode_search_s, "move_acceptance": dict(result.move_acceptance),
        "n_components": result.n_components, "widths": dict(result.widths),
        "limits": list(result.limits), "compile_s": result.compile_s,
        "stage_s": dict(result.stage_s), "method": result.method, "smc": dict(result.smc),
        "basin": dict(result.basin), "priors": dict(result.priors),
        "default_prior": result.default_prior,
        "modes": [{"cost": m.cost, "log_evidence": m.log_evidence, "weight": m.weight,
                   "values": dict(m.values), "kind": m.kind} for m in modes],
        "convergence": None if conv is None else {
            "names": list(conv.names), "rhat": list(map(float, conv.rhat)),
            "ess_bulk": list(map(float, conv.ess_bulk)),
            "ess_tail": list(map(float, conv.ess_tail)),
            "tau": None if conv.tau is None else list(map(float, conv.tau)),
            "steps": conv.steps},
    }
    raw = xr.Dataset({k: xr.DataArray(v[1], dims=v[0]) for k, v in data.items()},
                     attrs={"summary": json.dumps(_plain(summary)),
                            "fit": json.dumps(finite(result.fit.to_dict()))})
    idata.add_groups({_GROUP: raw}, warn_on_custom_groups=False)
    idata.to_netcdf(str(path))


def _plain(x):
    """JSON-safe: NaN and ±inf as strings that :func:`_unplain` reads back."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return x if np.isfinite(x) else repr(x)
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    return x


def _unplain(x):
    if isinstance(x, dict):
        return {k: _unplain(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_unplain(v) for v in x]
    if isinstance(x, str) and x in ("nan", "inf", "-inf"):
        return float(x)
    return x


def load(path, fit, effects: dict | None, cls):
    """The ``cls`` (:class:`PosteriorResult`, given by its ``load``: this module does not
    import it) that :func:`save` wrote to ``path``; ``fit`` the live
    :class:`~hdid.FitResult` it was sampled from (else the saved fit, without its log)."""
    import arviz as az

    from .._errors import HdidError
    from .diagnostics import Convergence
    from .modes import Mode

    try:
        idata = az.from_netcdf(str(path))
        raw = idata[_GROUP]
        summary = _unplain(json.loads(raw.attrs["summary"]))
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise HdidError(f"{path}: not a posterior saved by hdid (PosteriorResult.save / "
                        f"hdid fit --posterior --chains OUT.nc) ({type(exc).__name__}: "
                        f"{exc}); save it again with this hdid") from None
    if summary.get("saved_version", 0) > SAVED_VERSION:
        raise HdidError(f"{path}: written by a newer hdid; upgrade hdid to read it")
    if fit is None:
        from .._results._result import FitResult

        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / "fit.json"
            p.write_text(raw.attrs["fit"])
            fit = FitResult.load(p, effects=effects)
    arr = {k: np.asarray(raw[k].values) for k in raw.data_vars}
    names = summary["names"]
    samples = {n: arr[f"samples_{i}"] for i, n in enumerate(names["samples"])}
    derived = {n: arr[f"derived_{i}"] for i, n in enumerate(names["derived"])}
    modes = [Mode(u=arr["mode_u"][k], cost=m["cost"], cov=arr["mode_cov"][k],
                  log_evidence=m["log_evidence"], weight=m["weight"], values=m["values"],
                  kind=m["kind"]) for k, m in enumerate(summary["modes"])]
    c = summary["convergence"]
    conv = None if c is None else Convergence(
        c["names"], np.asarray(c["rhat"], dtype=float), np.asarray(c["ess_bulk"], dtype=float),
        np.asarray(c["ess_tail"], dtype=float),
        None if c["tau"] is None else np.asarray(c["tau"], dtype=float), c["steps"])
    keep = ("burn", "thin", "warnings", "seed", "wall_time_s", "temper", "residual_rho1",
            "burn_in", "mode_search_s", "move_acceptance", "n_components", "widths", "limits",
            "compile_s", "stage_s", "method", "smc", "basin", "priors", "default_prior")
    return cls(
        samples=samples, derived=derived, chain=arr["chain"], labels=summary["labels"],
        tau=arr["tau"], acceptance=arr["acceptance"], fit=fit, draws=arr["draws"],
        modes=modes, mode_share=arr.get("mode_share"), tau_emcee=arr.get("tau_emcee"),
        convergence=conv, **{k: summary[k] for k in keep})
