"""EMPS: hdid's fit against the authors' IDIM-LS parameters, on the validation log.

    python data/real/emps/compare.py [FIT.json] [--data DIR]

DIR (default ``../shared/data/real/emps`` beside the repository) holds ``emps_train.csv``
and ``emps_pulses.csv`` as ``convert.py`` writes them (README.md: where to get the
benchmark's ``.mat`` files). FIT.json is what ``hdid fit DIR/emps_train.csv --ratio 1
--add torque_offset --json FIT.json`` writes (fitted here when not given). Two criteria,
the same for both parameter sets, both on ``emps_pulses.csv`` (the validation set with
force pulses, never used in any fit):

1. the authors' cross-test validation (``Script_IDIM_LS_CTV.m``): the force predicted by
   the inverse model from the position (4th-order Butterworth at 100 Hz, zero phase,
   central differences, 50 edge samples dropped, decimated by 10), relative error
   ``‖F − F̂‖/‖F‖`` in %; hdid's friction law (its Stribeck term included) in place of
   ``Fc·sign(v)``;
2. hdid's multiple-shooting prediction: the position simulated from the logged force
   with the parameters held, each 0.2 s window from its own fitted start position and
   velocity; RMS position error [m].
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
#: Where the converted logs live: never in this repository (../shared/data/real/emps).
DATA = ROOT.parent / "shared" / "data" / "real" / "emps"
TRAIN, PULSES = "emps_train.csv", "emps_pulses.csv"
#: The authors' IDIM-LS estimates (EMPS_Description.pdf; Script_IDIM_LS.m on DATA_EMPS).
IDIM_LS = {"inertia": 95.11, "c_v": 203.5, "tau_c": 20.39, "tau_0": -3.16}


def _diffcent(x, h):
    d = np.empty_like(x)
    d[1:-1] = (x[2:] - x[:-2]) / (2 * h)
    d[0], d[-1] = (x[1] - x[0]) / h, (x[-1] - x[-2]) / h
    return d


def inverse_model_error(csv: Path, p: dict[str, float]) -> float:
    """Criterion 1: relative force error [%] of the inverse model with parameters ``p``."""
    import pandas as pd
    from scipy.signal import butter, decimate, filtfilt

    d = pd.read_csv(csv)
    h = float(d["time"].iloc[1] - d["time"].iloc[0])
    b, a = butter(4, 100.0 / (0.5 / h))
    q = filtfilt(b, a, d["theta"].to_numpy())
    v = _diffcent(q, h)
    acc = _diffcent(v, h)
    s = slice(49, None)
    v, acc, force = v[s], acc[s], d["motor_torque"].to_numpy()[s]
    tau_c = p["tau_c"]
    tau_s = p.get("tau_s", tau_c)
    fric = tau_c
    if "v_s" in p and tau_s != tau_c:
        fric = tau_c + (tau_s - tau_c) * np.exp(-np.abs(v / p["v_s"]) ** p.get("delta", 1.0))
    model = p["inertia"] * acc + p["c_v"] * v + np.sign(v) * fric + p["tau_0"]
    y, yhat = decimate(force, 10), decimate(model, 10)
    return float(100 * np.linalg.norm(y - yhat) / np.linalg.norm(y))


def shooting_rms(csv: Path, p: dict[str, float]) -> float:
    """Criterion 2: multiple-shooting RMS position error [m] with ``p`` held."""
    import hdid

    model = hdid.Model.default(ratio=1.0).with_effect(hdid.TorqueOffset(tau_0=0.0))
    values = {"tau_s": p.get("tau_s", p["tau_c"]), **p}
    values = {k: v for k, v in values.items() if k in model.parameter_specs()}
    model = model.replace(**values)
    r = hdid.fit_driven(csv, model, fix=list(model.parameter_specs()))
    return float(r.rms["wg_rad"])


def main(argv):
    argv = list(argv)
    data = DATA
    if "--data" in argv:
        k = argv.index("--data")
        data = Path(argv[k + 1])
        del argv[k:k + 2]
    train, val = data / TRAIN, data / PULSES
    for path in (train, val):
        if not path.exists():
            raise SystemExit(f"{path} not found: convert the benchmark's .mat files with "
                             "data/real/emps/convert.py (data/real/emps/README.md) or pass --data DIR")
    if argv:
        fit = json.loads(Path(argv[0]).read_text())
    else:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "fit.json"
            subprocess.run([sys.executable, "-m", "hdid.cli", "fit", str(train), "--ratio", "1",
                            "--add", "torque_offset", "--json", str(out), "-q"], check=True, cwd=ROOT)
            fit = json.loads(out.read_text())
    ours = {k: v["value"] for k, v in fit["parameters"].items()}
    print(f"{'':12} {'hdid':>10} {'IDIM-LS':>10}")
    for k in IDIM_LS:
        print(f"{k:12} {ours[k]:10.4g} {IDIM_LS[k]:10.4g}  ({100 * (ours[k] / IDIM_LS[k] - 1):+.1f} %)"
              f"  std {fit['parameters'][k]['std']:.3g}")
    print(f"inverse-model force error on {PULSES} [%]: hdid {inverse_model_error(val, ours):.3f}, "
          f"IDIM-LS {inverse_model_error(val, IDIM_LS):.3f}")
    print(f"multiple-shooting position RMS on {PULSES} [m]: hdid {shooting_rms(val, ours):.4g}, "
          f"IDIM-LS {shooting_rms(val, IDIM_LS):.4g}")


if __name__ == "__main__":
    main(sys.argv[1:])
