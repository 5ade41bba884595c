"""Independent, high-accuracy, event-driven reference simulator of the free-motion test.

This package is the ground truth against which the JAX simulator is tested and, through
:mod:`hdid.reference.logs`, the generator of the synthetic logs in ``data/synthetic``.  It
deliberately uses nothing but numpy and scipy (no JAX), and shares no code with the JAX
simulator.

Model (all angles at the wave generator, WG, measured from the spring's zero)::

    I·θ̈ = −T_k(θ/N)/N − τ_f(ω) + τ_x(θ, ω),      T_k(d) = k1·d + k2·d³

    sliding (ω ≠ 0, s = sign ω):
        τ_f = s·(τ_c + (τ_s − τ_c)·exp(−|ω/v_s|^δ)) + c_v·ω

    at rest (ω = 0, at release or whenever the velocity reaches zero), with
    F = −T_k(θ/N)/N + τ_x(θ, 0) the net non-friction torque:
        |F| ≤ τ_s  →  the WG sticks, exactly and for ever;
        |F| > τ_s  →  it slides in direction sign(F), the friction at ω = 0⁺ being τ_s.

``τ_x`` is the optional ``extra_torque(theta, omega)`` (zero by default); the optional
``extra_holding(theta)`` adds static capacity (the stick test becomes
``|F| ≤ τ_s + extra_holding(θ)``) and the optional ``dahl = (f_h, sigma_h)`` adds a Dahl
hysteresis element, an extra state ``z`` with ``dz/dt = sigma_h·ω·(1 − s·z/f_h)`` whose
torque ``−z`` enters both the motion and ``F``; ``z(release) = sign(θ0)·f_h·(1 −
exp(−sigma_h·|θ0|/f_h))`` (the servo twisted the WG monotonically from the spring's zero).
These hooks let the test suite hide effects in synthetic logs with code that shares
nothing with the JAX effects.

Numerics
--------
Each sliding segment is integrated with :func:`scipy.integrate.solve_ivp` (DOP853, dense
output) with the friction direction ``s`` held *fixed*, and a terminal, direction-aware event
on ``s·ω = 0`` (crossing downwards).  Within a segment ``|ω|`` is evaluated as
``max(s·ω, 0)``, so the right-hand side is smooth on the segment's side of ``ω = 0`` and
``|ω/v_s|^δ`` is never evaluated at a negative base; at ``ω = 0`` it is exactly ``0`` (δ > 0),
so the friction there is exactly ``s·τ_s``.  At every event the state is reset to ``ω = 0``
exactly and the stick/slide rule above is applied.  A guard (``max_events``) stops Zeno
chattering by sticking after that many events.

The package's parts: the spring and its stick band (``_spring``), the event-driven
trajectory (``_events``) and the trajectory read like a log (``_sampled``); the driven
joint's reference simulator (``_driven``); and the synthetic logs built on them, for the
tests, benchmarks, calibrations and notebooks: :mod:`hdid.reference.logs`.
"""

from __future__ import annotations

from ._events import ReferenceTrajectory, reference_trajectory
from ._sampled import simulate_reference, simulate_reference_dense
from ._spring import ExtraTorque, spring_torque_wg, stick_band_halfwidth  # noqa: F401

__all__ = [
    "ReferenceTrajectory",
    "reference_trajectory",
    "simulate_reference",
    "simulate_reference_dense",
    "stick_band_halfwidth",
    "spring_torque_wg",
]
