"""Convert the EMPS benchmark's MATLAB files into hdid driven logs (CSV, SI units).

    python data/real/emps/convert.py [SOURCE_DIR]

SOURCE_DIR holds ``DATA_EMPS.mat`` and ``DATA_EMPS_PULSES.mat`` as distributed by the
benchmark authors (default ``../shared/data/real/emps`` beside the repository).
Writes ``train.csv`` (from DATA_EMPS.mat, the estimation set) and ``validate.csv``
(from DATA_EMPS_PULSES.mat, the validation set with force pulses) next to this script:

* ``time`` [s]: ``k · 1 ms``. The files' ``t`` is that grid up to 3e-8 s of rounding
  (float32 jitter in the logger), far below the sample period.
* ``theta`` [m]: ``qm``, the motor encoder's position converted to the load side of the
  ball screw (a linear axis: hdid's "angle" is metres, its "inertia" a mass in kg and its
  torques newtons; gear ratio 1, no output encoder).
* ``motor_torque`` [N]: ``gtau · vir``, the drive voltage (the controller's output,
  force pulses included in the validation set) times the drive gain gtau = 35.15 N/V.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.io

HERE = Path(__file__).resolve().parent
DEFAULT_SOURCE = HERE.parents[3] / "shared" / "data" / "real" / "emps"
FILES = {"train.csv": "DATA_EMPS.mat", "validate.csv": "DATA_EMPS_PULSES.mat"}
PERIOD = 1e-3


def convert(mat_path: Path, csv_path: Path) -> None:
    d = scipy.io.loadmat(mat_path)
    t = np.asarray(d["t"], dtype=float).ravel()
    qm = np.asarray(d["qm"], dtype=float).ravel()
    force = float(np.asarray(d["gtau"]).ravel()[0]) * np.asarray(d["vir"], dtype=float).ravel()
    grid = np.arange(t.size) * PERIOD
    if np.max(np.abs(t - grid)) > 1e-6:
        raise SystemExit(f"{mat_path}: t is not the 1 kHz grid (off by {np.max(np.abs(t - grid)):.3g} s)")
    with open(csv_path, "w") as f:
        f.write("time,theta,motor_torque\n")
        for row in zip(grid, qm, force):
            f.write("%.3f,%.10g,%.10g\n" % row)


def main(argv: list[str]) -> None:
    source = Path(argv[0]) if argv else DEFAULT_SOURCE
    for csv_name, mat_name in FILES.items():
        convert(source / mat_name, HERE / csv_name)
        print(f"wrote {HERE / csv_name} from {source / mat_name}")


if __name__ == "__main__":
    main(sys.argv[1:])
