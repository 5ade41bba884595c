"""The library's Python wording as the command line's: a message that names a keyword
argument (``max_steps ≥ 40000``, ``prior={'k2': (value, sd)}``) reaches the person at the
terminal naming the flag that sets it (``--steps ≥ 40000``, ``--prior k2=VALUE,SD``).

The library speaks to Python callers and stays as it is; the commands pass every line they
print (reports, warnings, errors) through :func:`to_flags`. The JSON files keep the
library's words (they are the library's ``to_dict``).
"""

from __future__ import annotations

import re

import click

#: The Python arguments a flag sets (and ``moves``, which none does but which the posterior
#: names beside them).
_PY = (r"(?:max_steps|n_steps|n_walkers|n_particles|moves|method|prior|fix|seed|"
       r"torque_constant|output_counts_per_rev|workers|band_bracket|resolution|counts_per_rev|"
       r"release_time|inertia_prior|free_inertia|n_starts|start_from_model|inertia|ratio)")
_VALUE = r"(?:=(?:'[^']*'|\"[^\"]*\"))?"
_FLAG = r"--[a-z][\w/-]*"

# (pattern, replacement), applied in order; the specific forms before the bare names.
_EVERY_COMMAND: tuple[tuple[str, str], ...] = (
    # a message that names both keeps the flag: "n_walkers (--walkers) = 4",
    # "method='smc' (--sampler smc)", "prior= / --prior K=VALUE,SD", "--fix / fix="
    (rf"\b{_PY}{_VALUE}(?:, {_PY}{_VALUE})* \(({_FLAG}(?: [^()]*?)?)\)", r"\1"),
    (rf"\b{_PY}=\s*/\s*({_FLAG})", r"\1"),
    (rf"({_FLAG})\s*/\s*{_PY}=", r"\1"),
    # posterior (hdid._posterior): chain length, walkers, particles, sampler, priors
    (r"\bmax_steps\s*(≥|>=)\s*", r"--steps \1 "),
    (r"run longer: max_steps\b", "run longer: --steps"),
    (r"\bmax_steps\b|\bn_steps\b", "--steps"),
    (r"method='smc'|method=\"smc\"", "--sampler smc"),
    (r"method='emcee'|method=\"emcee\"", "--sampler emcee"),
    (r"\bn_walkers\b", "--walkers"),
    (r"\bn_particles\b", "--particles"),
    (r"\(max_rounds\): the particles are not posterior draws\. Raise max_rounds",
     "(its round limit): the particles are not posterior draws. Use --sampler emcee, or "
     "more --particles"),
    (r"prior=\{'([^']+)': \(value, sd\)\}", r"--prior \1=VALUE,SD"),
    # fitting and batches
    (r"band_bracket=False", "no --band-bracket"),
    (r"run with workers=1", "leave --workers out"),
    (r"\bworkers=(\S+) needs", r"--workers \1 needs"),
    # driven logs (hdid._log._columns)
    (r"\btorque_constant=KT\b", "--torque-constant KT"),
    (r"\btorque_constant\b", "--torque-constant"),
    (r"\boutput_counts_per_rev=N\b", "--output-counts-per-rev N"),
    (r"\boutput_counts_per_rev\b", "--output-counts-per-rev"),
)

#: Per command: ``diagnose``'s forward-selection steps are ``--selection-steps`` (``--steps``
#: is ``fit``'s posterior chain length); the library's verdict advises "--steps 2".
_PER_COMMAND: dict[str, tuple[tuple[str, str], ...]] = {
    "diagnose": ((r"\btry --steps (\d+)", r"try --selection-steps \1"),),
}


def to_flags(text: str, command: str | None = None) -> str:
    """``text`` with the library's Python argument names replaced by the flags of
    ``command`` (default: the command being run)."""
    if command is None:
        ctx = click.get_current_context(silent=True)
        command = ctx.info_name if ctx is not None else None
    for pattern, repl in _PER_COMMAND.get(command or "", ()):
        text = re.sub(pattern, repl, text)
    for pattern, repl in _EVERY_COMMAND:
        text = re.sub(pattern, repl, text)
    return text
