"""Stribeck friction at the wave generator (paper eq. 5, without the viscous term)."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractFriction, Motion, ScalePrior, StartValues, parameter, positive_power
from ._candidate import Candidate


#: Median of the Stribeck velocity's prior (and its start) as a fraction of the log's
#: peak speed, and the prior's sd in log (class docstring).
V_S_FRACTION = 0.05
V_S_PRIOR_SD = 1.0
#: The shape exponent's interval (its transform), prior median and sd in the logit.
DELTA_INTERVAL = (0.3, 4.0)
DELTA_MEDIAN = 1.0
DELTA_PRIOR_SD = 0.8
#: The least-squares fit's weak prior rows on v_s and delta (transformed space; delta's
#: centred on its interval's middle): sd 2. The physical priors above are the posterior's
#: (``posterior_prior``): as the fit's rows they sent the start grid into a poorer basin of
#: an independent pendulum-drop log (tests/test_real_logs_synthetic.py: v_s 154 rad/s,
#: χ² 1186 against 583 at the truth's shape, mgl 6.5 sd off, nothing flagged).
LSQ_PRIOR_SD = 2.0
#: The posterior's default prior of a dry-friction torque (``tau_c``, ``tau_s``): log-normal
#: around the friction level the log's ring-down shows (``Scales.torque``), a factor 10.5
#: either way at 95 %. It replaces the flat-in-value prior of ``tau_c`` (issue 34's
#: decision (a): that prior put mass on a Coulomb limit the data do not support, and no
#: sampler measured converged on it); ``sample_posterior(default_prior="flat")`` keeps it.
FRICTION_TORQUE_PRIOR = ScalePrior(
    lambda s: s.torque,
    "the friction torque of the log's ring-down: k_wg × amplitude lost per run / 4, at "
    "least 2 % of the spring torque at the release amplitude")


class StribeckFriction(AbstractFriction):
    r"""Coulomb friction with a Stribeck rise to a static (breakaway) level.

    Sliding: ``tau_f = s·(tau_c + (tau_s − tau_c)·exp(−|ω/v_s|^delta))`` opposing the
    motion (``s`` the sliding direction). At rest it holds any torque up to ``tau_s``:
    this is what makes the wave generator stop dead inside the stick band
    ``|T_k(θ/N)/N| ≤ tau_s`` — the "backlash band" of the paper.

    Residual mark when missing or wrong: rest points off, amplitude decrement per
    half-cycle wrong (Coulomb removes ``2·tau_c/k`` per swing), residual that flips with
    the sign of the velocity and peaks just before rest.

    Priors of the posterior (:attr:`posterior_prior`, :attr:`ordered`; each relative to
    the log in hand or dimensionless, none encodes one gear's size). The least-squares fit
    keeps its weak rows (sd 2 in log v_s around the same start, sd 2 in delta's logit
    around its interval's middle, ``LSQ_PRIOR_SD``): as the fit's rows these physical
    priors sent the start grid into a poorer basin of an independent pendulum-drop log.

    - ``v_s``: log-normal, median 5 % of the log's peak speed (``Scales.speed``), sd 1 in
      log (95 % between 0.7 % and 37 % of that speed). Footing: ``v_s`` is the speed
      where breakaway gives way to Coulomb friction; for the law to describe what the log
      shows, that transition has to lie inside the speeds the log covers — well below its
      peak (above it the law is Coulomb friction at ``tau_s`` plus an unresolved tail) and
      above the speeds the encoder resolves (one step per sample is 0.7 % of the peak
      speed on the paper's design, the prior's lower 2.5 % point). The previous sd of 2 (a factor e² = 7.4 either way, 2σ beyond the peak speed)
      let the posterior run along the Coulomb limit of the law (low ``tau_c``, high
      ``c_v``, ``v_s`` and low ``delta``), where emcee did not converge on the paper design
      in 20 000 steps (docs/decisions/stribeck-priors.md).
    - ``delta``: logit-normal on its interval (0.3, 4), median 1 (the exponential law),
      sd 0.8 in the logit: 95 % between 0.47 and 2.3. Footing: the shape exponents
      published for lubricated contacts lie between ½ and 2 (½–1 Bo & Pavelescu,
      1 Tustin/exponential, 2 Armstrong-Hélouvry's Gaussian law). The previous logit sd of
      2 around the interval's middle was U-shaped in the value and put the paper log's
      posterior at the interval's top (median 2.9) wherever the data cannot see the shape.
    - ``tau_c``: flat in its *value* (``flat_in_value``, like ``k2`` and ``c_v``), on the
      box of ±7 in log around the least-squares value that every parameter without a
      prior of its own has. Footing: ``tau_c`` is the coefficient of a term that may
      vanish — with ``tau_c → 0`` the Stribeck+viscous law becomes a Stribeck hump on a
      viscous line (``tau_s·e + c_v·ω``), its Coulomb limit, a law in its own right. A
      prior flat in the log gives that "absent" end equal mass per decade down to the
      box's floor, so where the data cannot exclude the limit the posterior is set by an
      arbitrary box: on the shipped paper log (``data/synthetic/csf8_paper.csv``) the
      least-squares cost rises by less than 1.6 (χ²) from the fit's ``tau_c`` of 2.2 mN m
      down to 6 µN m along laws with ``v_s`` ≈ 20–24 rad/s and ``c_v`` ≈ 5–7e-5
      (docs/decisions/friction-coordinates.md, tau-c-flat-in-value.md). Flat in value, the mass
      there is proportional to the torque range the data allow: the data bound ``tau_c``
      above; where they do not bound it below, the posterior says so (a warning, see
      ``hdid._posterior.limits``), instead of a box-made interval. A
      ``prior=`` of the user's (a datasheet's Gaussian, the calibration's ``--prior
      physical``) replaces it.
    - ``tau_s ≥ tau_c`` (:attr:`ordered`): breakaway (static) friction is by definition
      at least the sliding friction it gives way to; the posterior gives ``tau_s < tau_c``
      zero density. Chosen as a constraint rather than a reparameterisation
      ``tau_s = tau_c + excess``: the fitted and reported parameters (names, JSON, saved
      fits, diagnose's candidates) stay ``tau_c`` and ``tau_s``; the least-squares fit
      keeps the unconstrained optimum and flags ``tau_s ≤ tau_c`` as a symptom (nested
      Coulomb check) instead of pinning it to the boundary.
    """

    tau_c: Float[ArrayLike, ""] = parameter(
        "N m", "Coulomb friction torque at the wave generator",
        start=lambda s: s.torque, flat_in_value=True, sample_in_value=True)
    # breakaway above Coulomb, and enough to hold the largest logged rest point
    tau_s: Float[ArrayLike, ""] = parameter(
        "N m", "static (breakaway) friction torque at the wave generator",
        start=lambda s: max(1.3 * s.torque, 1.05 * s.k_wg * s.band))
    # Physical priors (transformed space; footing in the class docstring): the
    # Stribeck velocity log-normal around 5 % of the log's peak speed, sd 1; the shape
    # exponent logit-normal with median 1, 95 % in [0.47, 2.3].
    v_s: Float[ArrayLike, ""] = parameter(
        "rad/s", "Stribeck velocity (wave generator)",
        prior=(None, LSQ_PRIOR_SD), start=lambda s: V_S_FRACTION * s.speed)
    delta: Float[ArrayLike, ""] = parameter(
        "1", "Stribeck shape exponent",
        transform=("interval", *DELTA_INTERVAL), prior=(0.0, LSQ_PRIOR_SD))

    key: ClassVar[str] = "stribeck"
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=90,
        mark="the residual flips with the sign of the velocity and peaks just before rest: "
             "static friction above Coulomb is missing",
        experiment="1 kHz sampling around the reversals resolves the Stribeck rise",
    )
    #: breakaway at least Coulomb friction (imposed by the posterior)
    ordered: ClassVar[tuple[tuple[str, str], ...]] = (("tau_c", "tau_s"),)
    #: the physical priors, in the posterior (class docstring)
    posterior_prior: ClassVar[dict] = {"v_s": (None, V_S_PRIOR_SD),
                                       "delta": (DELTA_MEDIAN, DELTA_PRIOR_SD),
                                       "tau_c": FRICTION_TORQUE_PRIOR,
                                       "tau_s": FRICTION_TORQUE_PRIOR}

    @classmethod
    def start_from(cls, values: dict[str, float]) -> StribeckFriction:
        """Starting values for ``--add stribeck`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(**s.stribeck)

    def derived(self, inertia, k_wg):
        """Friction torques per unit inertia (decelerations, what the motion fixes when
        the inertia is only assumed)."""
        del k_wg
        return {"tau_c/inertia": self.tau_c / inertia, "tau_s/inertia": self.tau_s / inertia}

    def sliding_magnitude(self, omega: Float[Array, ""]) -> Float[Array, ""]:
        """Friction magnitude [N m] while sliding at ``omega`` [rad/s]."""
        x = positive_power(jnp.abs(omega) / self.v_s, self.delta)
        return self.tau_c + (self.tau_s - self.tau_c) * jnp.exp(-x)

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -motion.direction * self.sliding_magnitude(motion.omega)

    def holding_torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del motion, state
        return jnp.asarray(self.tau_s, dtype=float)
