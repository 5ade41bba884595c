"""Convert the EMPS benchmark's MATLAB files into hdid driven logs (CSV, SI units).

    python data/real/emps/convert.py [SOURCE_DIR [OUT_DIR]]

SOURCE_DIR holds ``DATA_EMPS.mat`` and ``DATA_EMPS_PULSES.mat`` as distributed by the
benchmark authors (default ``../shared/data/real/emps`` beside the repository); OUT_DIR
(default SOURCE_DIR) receives ``emps_train.csv`` (from DATA_EMPS.mat, the estimation
set) and ``emps_pulses.csv`` (from DATA_EMPS_PULSES.mat, the validation set with force
pulses). The CSVs are never kept in this repository.

* ``time`` [s]: ``k · 1 ms``. The files' ``t`` is that grid up to 3e-8 s of rounding
  (float32 jitter in the logger), far below the sample period.
* ``theta`` [m]: ``qm``, the motor encoder's position converted to the load side of the
  ball screw (a linear axis: hdid's "angle" is metres, its "inertia" a mass in kg and its
  torques newtons; gear ratio 1, no output encoder).
* ``motor_torque`` [N]: ``gtau · vir``, the drive voltage (the controller's output,
  force pulses included in the validation set) times the drive gain gtau = 35.15 N/V.
* ``run`` = 1, ``setup`` = A: one continuous run of one set-up.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.io

HERE = Path(__file__).resolve().parent
DEFAULT_SOURCE = HERE.parents[3] / "shared" / "data" / "real" / "emps"
FILES = {"emps_train.csv": "DATA_EMPS.mat", "emps_pulses.csv": "DATA_EMPS_PULSES.mat"}
PERIOD = 1e-3


def convert(mat_path: Path, csv_path: Path) -> None:
    import pandas as pd

    d = scipy.io.loadmat(mat_path)
    t = np.asarray(d["t"], dtype=float).ravel()
    qm = np.asarray(d["qm"], dtype=float).ravel()
    force = float(np.asarray(d["gtau"]).ravel()[0]) * np.asarray(d["vir"], dtype=float).ravel()
    grid = np.arange(t.size) * PERIOD
    if np.max(np.abs(t - grid)) > 1e-6:
        raise SystemExit(f"{mat_path}: t is not the 1 kHz grid (off by {np.max(np.abs(t - grid)):.3g} s)")
    frame = pd.DataFrame({"time": grid, "theta": qm, "motor_torque": force, "run": 1, "setup": "A"})
    frame.to_csv(csv_path, index=False, float_format="%.10g")


def main(argv: list[str]) -> None:
    source = Path(argv[0]) if argv else DEFAULT_SOURCE
    out = Path(argv[1]) if len(argv) > 1 else source
    out.mkdir(parents=True, exist_ok=True)
    for csv_name, mat_name in FILES.items():
        if not (source / mat_name).exists():
            raise SystemExit(f"{source / mat_name} not found: download DATA_EMPS.mat and "
                             "DATA_EMPS_PULSES.mat first (data/real/emps/README.md)")
        convert(source / mat_name, out / csv_name)
        print(f"wrote {out / csv_name} from {source / mat_name}")


if __name__ == "__main__":
    main(sys.argv[1:])
