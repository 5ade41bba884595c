"""The ``hdid`` command: the group and its commands (one file per command)."""

from __future__ import annotations

import click

from ._common import _Group
from .design import design_cmd
from .diagnose import diagnose_cmd
from .fit import fit_cmd
from .simulate import simulate_cmd


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="hdid")
def main():
    """hdid — identify harmonic-drive physics (stiffness, Stribeck friction, stick band,
    inertia) from encoder logs of the elastic-slide-free-motion test."""
    # An application configures its process before JAX and equinox are imported:
    # float64, the compilation cache, equinox's checks as NaN (cacheable programs).
    from .._config import configure

    configure()


main.add_command(fit_cmd)
main.add_command(diagnose_cmd)
main.add_command(simulate_cmd)
main.add_command(design_cmd)
