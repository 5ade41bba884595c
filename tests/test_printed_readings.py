"""Logs as loggers print them: readings with fixed decimals, in degrees, time in ms.

The encoder step must come from the readings' levels within their printing precision,
never be the print unit itself, and give the same physics as the full-precision log; a
log whose numbers are implausible for their declared units says so on its first line.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hdid import read_log
from hdid._log._resolution import find_step, print_precision
from hdid.cli import main

ROOT = Path(__file__).resolve().parents[1]
SYN = ROOT / "data" / "synthetic"
TRUTH = json.loads((SYN / "truth.json").read_text())
FREE = ("csf8_paper.csv", "csf8_rich_1khz.csv", "hidden_hysteresis_1khz.csv")
DECIMALS = (4, 5, 6, 8, 10, 12)
#: A step found in the readings is their grid's least-squares fit: within a print unit
#: over hundreds of steps, far inside the 1 % asked for.
STEP_RTOL = 0.01


def _write(name: str, path: Path, *, decimals: int | None = None, degrees: bool = False,
           ms: bool = False) -> Path:
    """The shipped log ``name`` written as a logger would: fixed decimals, theta in
    degrees (header ``theta [deg]``) or time in milliseconds (``time [ms]``)."""
    d = pd.read_csv(SYN / name)
    if degrees:
        d["theta"] = np.degrees(d["theta"])
        d = d.rename(columns={"theta": "theta [deg]"})
    if ms:
        d["time"] = d["time"] * 1000.0
        d = d.rename(columns={"time": "time [ms]"})
    d.to_csv(path, index=False, float_format=None if decimals is None else f"%.{decimals}f")
    return path


VARIANTS = (
    [(n, {"decimals": k}) for n in FREE for k in DECIMALS]
    + [(n, {"decimals": 5, "degrees": True}) for n in FREE]
    + [(n, {"ms": True}) for n in FREE]
)


@pytest.mark.parametrize("name, how", VARIANTS, ids=lambda v: str(v))
def test_step_found_in_printed_readings(tmp_path, name, how):
    path = _write(name, tmp_path / "log.csv", **how)
    log = read_log(path)
    step = TRUTH[name]["step_rad"]
    # Every variant here tells its grid: at 4 decimals in rad (the coarsest) the print unit
    # is 1/15.7 step, so a wrong grid passes one level with chance ≈ 2/15.7 and all of the
    # log's hundreds of levels with chance < 1e-100 (hdid._log._resolution).
    assert log.resolution is not None, log.resolution_note
    assert log.resolution_source == "estimated"
    assert log.resolution == pytest.approx(step, rel=STEP_RTOL)
    # the printing precision is read from the text, in rad
    k = how.get("decimals")
    if k is not None:
        unit = 10.0**-k * (math.pi / 180.0 if how.get("degrees") else 1.0)
        assert log.print_unit == pytest.approx(unit, rel=1e-9)
        # the print unit is never the step
        assert log.resolution > 4 * log.print_unit


@pytest.mark.parametrize("how", [{"decimals": k} for k in DECIMALS] + [{"ms": True}],
                         ids=lambda v: str(v))
def test_counts_printed_with_decimals(tmp_path, how):
    name = "csf8_paper_counts.csv"
    log = read_log(_write(name, tmp_path / "log.csv", **how), counts_per_rev=4000)
    assert log.resolution == pytest.approx(TRUTH[name]["step_rad"], rel=1e-12)


def test_output_step_found_in_printed_theta_out(tmp_path):
    name = "driven_csf8.csv"
    d = pd.read_csv(SYN / name)
    path = tmp_path / "driven.csv"
    # 7 decimals: the output step 1.2e-5 rad is 120 print units
    d.to_csv(path, index=False, float_format="%.7f")
    log = read_log(path)
    assert log.output_resolution == pytest.approx(TRUTH[name]["output_step_rad"], rel=STEP_RTOL)
    assert log.resolution == pytest.approx(TRUTH[name]["step_rad"], rel=STEP_RTOL)


def test_mrad_and_significant_digits(tmp_path):
    name = "csf8_paper.csv"
    d = pd.read_csv(SYN / name)
    step = TRUTH[name]["step_rad"]
    m = d.assign(theta=d["theta"] * 1e3).rename(columns={"theta": "theta [mrad]"})
    m.to_csv(tmp_path / "mrad.csv", index=False, float_format="%.3f")  # 1e-6 rad
    log = read_log(tmp_path / "mrad.csv")
    assert log.resolution == pytest.approx(step, rel=STEP_RTOL)
    assert log.print_unit == pytest.approx(1e-6)
    d.to_csv(tmp_path / "g.csv", index=False, float_format="%.5g")  # %g: 5 significant digits
    log = read_log(tmp_path / "g.csv")
    assert log.resolution == pytest.approx(step, rel=STEP_RTOL)
    assert print_precision(np.array(["1.5708e-03", "-2.1e-01"])).kind == "digits"


def test_too_coarse_or_no_grid_is_said_not_guessed(tmp_path):
    name = "csf8_paper.csv"
    d = pd.read_csv(SYN / name)
    # 3 decimals: the print unit is 0.64 step — no encoder grid can be told; the print
    # unit is not reported as the step, the reason is
    d.to_csv(tmp_path / "coarse.csv", index=False, float_format="%.3f")
    log = read_log(tmp_path / "coarse.csv")
    assert log.resolution is None and log.resolution_source is None
    assert "print unit" in log.resolution_note
    # an analog sensor (Gaussian noise of 0.2 step) printed with 8 decimals: on no grid
    rng = np.random.default_rng(3)
    noisy = d.assign(theta=d["theta"] + rng.normal(0.0, 3e-4, len(d)))
    noisy.to_csv(tmp_path / "noisy.csv", index=False, float_format="%.8f")
    log = read_log(tmp_path / "noisy.csv")
    assert log.resolution is None and log.resolution_note


def test_offsets_per_run_do_not_matter():
    # two runs on one grid, each with its own offset (not a multiple of the step), printed
    # to 1/20 of the step
    q, p = 2 * math.pi / 4000, 2 * math.pi / 4000 / 20
    rng = np.random.default_rng(0)
    k = rng.integers(-100, 100, size=(2, 300))
    x = (k * q + np.array([[0.0123456], [-0.0345678]])).ravel()
    printed = np.round(x / p) * p
    found = find_step(printed, p, [0, 300])
    assert found.step == pytest.approx(q, rel=1e-3)
    # the same levels read as one run (offsets mixed) are on no single grid
    assert find_step(printed, p, [0]).step is None


# ------------------------------------------------------------ same physics


#: Parameters and derived quantities compared between a printed variant and its
#: full-precision log.
PHYSICS = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")
#: The printing moves every reading by at most half a print unit: at 4 decimals 1/31 of
#: the step, an added noise of p/√12 whose variance is 0.4 % of the quantization floor's —
#: the estimates may move by a small fraction of their standard error, 0.2 σ at most (the
#: issue's bound).
WITHIN_SIGMA = 0.2


@pytest.fixture(scope="module")
def reference_fits():
    """The full-precision fits the printed variants are compared with (one per log)."""
    import hdid

    return {name: hdid.fit(read_log(SYN / name)) for name in ("csf8_rich_1khz.csv",
                                                               "csf8_paper.csv")}


@pytest.mark.parametrize("name, how", [
    ("csf8_rich_1khz.csv", {"decimals": 4}),  # the coarsest print that tells the step
    ("csf8_paper.csv", {"decimals": 5, "degrees": True}),
], ids=lambda v: str(v))
def test_printed_log_fits_the_same_physics(tmp_path, reference_fits, name, how):
    import hdid

    ref = reference_fits[name]
    fit = hdid.fit(read_log(_write(name, tmp_path / "log.csv", **how)))
    assert fit.resolution_source == "estimated"
    assert fit.resolution_rad == pytest.approx(ref.resolution_rad, rel=STEP_RTOL)
    for n in PHYSICS:
        a, b = fit.parameters[n], ref.parameters[n]
        assert abs(a.value - b.value) <= WITHIN_SIGMA * b.std, (n, a.value, b.value, b.std)
    for k in ("stick_band_halfwidth_rad", "natural_frequency_hz"):
        (a, _), (b, sb) = fit.derived[k], ref.derived[k]
        assert abs(a - b) <= WITHIN_SIGMA * sb, (k, a, b, sb)


# -------------------------------------------------------------------------- units


@pytest.fixture(scope="module")
def unit_fits(tmp_path_factory):
    """`hdid fit --json` of the paper log with theta in degrees and with time in ms, both
    without a unit in the header."""
    tmp = tmp_path_factory.mktemp("units")
    d = pd.read_csv(SYN / "csf8_paper.csv")
    out = {}
    for key, frame in (("deg", d.assign(theta=np.degrees(d["theta"]))),
                       ("ms", d.assign(time=d["time"] * 1000.0))):
        path = tmp / f"{key}.csv"
        frame.to_csv(path, index=False)
        res = CliRunner().invoke(main, ["fit", str(path), "--json", str(tmp / f"{key}.json")])
        assert res.exit_code == 0, res.output
        out[key] = (res.output, json.loads((tmp / f"{key}.json").read_text()))
    return out


@pytest.mark.parametrize("key, fix", [("deg", "theta [deg]"), ("ms", "time [ms]")])
def test_implausible_units_lead_the_report(unit_fits, key, fix):
    report, data = unit_fits[key]
    first = report.splitlines()[0]
    assert first.startswith("UNITS:") and f"`{fix}`" in first
    assert data["units_problem"] and f"`{fix}`" in data["units_problem"]


def test_plausible_units_say_nothing(tmp_path):
    # the same check on the right units: no problem (without a fit: the rule alone)
    from hdid._units import implausible_units

    assert implausible_units(sample_period=0.004, swing=0.157, ratio=100.0,
                             band_halfwidth=0.047, step=2 * math.pi / 4000,
                             geared_spring=True) is None


# ---------------------------------------------------------------- a wrong step


@pytest.fixture(scope="module")
def wrong_step_posterior():
    """`hdid fit --posterior` of the paper log with a given step 100× too fine: the fit's
    residual (0.24 of the true step) is ~24 of these steps, beyond the noise prior's
    20-step bound that used to put every walker at zero density (a traceback)."""
    step = TRUTH["csf8_paper.csv"]["step_rad"] / 100.0
    return CliRunner().invoke(main, [
        "fit", str(SYN / "csf8_paper.csv"), "--resolution", f"{step:.6g}", "--posterior",
        "--steps", "100", "--walkers", "40",
    ])


def test_wrong_step_is_blamed_not_the_model(wrong_step_posterior):
    res = wrong_step_posterior
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    out = res.output
    if res.exit_code == 2:  # refused: one line, no traceback
        assert len(out.strip().splitlines()) == 1 and "Traceback" not in out
        return
    assert res.exit_code == 0, out
    # the fit tracks every run to the readings' own spacing (100 of these steps): the
    # step is named as wrong, the model is not blamed
    assert "the step looks wrong" in out
    assert "the model does not describe this log" not in out
    # the posterior went on with the noise the log shows, and says so
    assert "σ_n is bounded by" in out


def test_step_against_readings_rule():
    from hdid._log._resolution import readings_spacing, step_against_readings

    q = 2 * math.pi / 4000
    rng = np.random.default_rng(1)
    theta = np.cumsum(rng.integers(-1, 2, size=(2, 200)), axis=1) * q  # adjacent counts
    lengths = [200, 150]
    assert readings_spacing(theta, lengths) == pytest.approx(q)
    # a residual of 0.25 q (a fit at the floor of q) against a step q/100: the step is wrong
    msg = step_against_readings(theta, lengths, q / 100, 0.25 * q, 3.0)
    assert msg is not None and "the step looks wrong" in msg
    # against the right step the residual is the model's: no step warning (the model is
    # blamed elsewhere when it is above the floor)
    assert step_against_readings(theta, lengths, q, 5.0 * q, 3.0) is None
    # a residual beyond the readings' own spacing's floor is the model's, whatever the step
    assert step_against_readings(theta, lengths, q / 100, 5.0 * q, 3.0) is None


# ------------------------------------------------ a few readings off the grid


def _walk(q, runs=3, n=400, seed=0):
    """Readings of ``runs`` runs on the grid ``q`` (each with its own offset): a swing that
    crosses levels at no fixed stride, then creeps to rest over neighbouring levels."""
    rng = np.random.default_rng(seed)
    out = []
    for r in range(runs):
        t = np.arange(n) / 100.0
        x = 0.3 * np.exp(-t) * np.cos(2 * math.pi * 0.8 * t + rng.uniform(0, 6))
        out.append(np.round(x / q) * q + rng.uniform(-1, 1))
    return out


def test_a_few_readings_off_the_grid_do_not_halve_the_step():
    # a logger's filled-in reading (the mean of the last two: half a step off) in 3 of
    # 1200 readings: the step is the grid all the others lie on, and the three are named
    q = 2 * math.pi / 4096
    runs = _walk(q)
    for r, k in ((0, 50), (1, 120), (2, 30)):
        runs[r][k] = runs[r][k - 1] + 0.5 * q  # e.g. the mean of -723 and -718 counts
    x = np.concatenate(runs)
    found = find_step(x, 1e-10, [0, 400, 800])
    assert found.step == pytest.approx(q, rel=1e-6)
    assert sorted(found.off_grid) == [50, 520, 830]
    assert all(abs(b - 0.5) < 1e-6 for b in found.off_by)


def test_a_finer_encoder_is_not_made_coarser():
    # readings on a genuinely finer grid (8192 counts) keep it: their levels fall on both
    # residues of the 4096 grid about equally (false acceptance bounded by 1e-6)
    q = 2 * math.pi / 8192
    x = np.concatenate(_walk(q, seed=1))
    found = find_step(x, 1e-10, [0, 400, 800])
    assert found.step == pytest.approx(q, rel=1e-6) and not found.off_grid


def test_more_than_a_percent_off_the_grid_is_the_finer_grid():
    # 2 % of the readings half a step off: not a handful of glitches (more than 1 %),
    # the grid that explains every level is kept
    q = 2 * math.pi / 4096
    runs = _walk(q, seed=2)
    for run in runs:
        run[10::50] += 0.5 * q
    x = np.concatenate(runs)
    found = find_step(x, 1e-10, [0, 400, 800])
    assert found.step == pytest.approx(q / 2, rel=1e-6) and not found.off_grid


REAL = ROOT.parent / "shared" / "data" / "real"
STS = REAL / "sts3215_drop"
BAM = REAL / "bam_xl330"


def _need(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path.name} not in {path.parent} (real logs stay outside the "
                    "repository: ../shared/data/real/README.md says where they come from)")


@pytest.mark.parametrize("mass_length", ["m0.535_l0.10", "m0.535_l0.15", "m0.741_l0.10",
                                         "m0.741_l0.15", "m0.969_l0.10", "m0.969_l0.15",
                                         "m1.168_l0.10", "m1.168_l0.15"])
def test_sts3215_logs_find_the_4096_count_step(mass_length):
    """The STS3215 output encoder has 4096 counts per revolution (README). In
    m0.535_l0.10 run kp4_2 the reading before the −π dropout is the mean of the two
    before it (−723, −718 counts → −720.5): half a count off, it alone forced a half-count
    grid; it is named as off the grid, not taken for a finer encoder."""
    path = STS / f"sts3215_{mass_length}.csv"
    _need(path)
    log = read_log(path)
    # the least-squares grid over hundreds of levels printed to 10 significant digits
    assert log.resolution == pytest.approx(2 * math.pi / 4096, rel=1e-6)
    off = [n for n in log.notes if "off the encoder grid" in n]
    if mass_length == "m0.535_l0.10":
        assert len(off) == 1 and "'kp4_2'" in off[0] and "0.50 step off" in off[0], off
    else:
        assert not off, off


def test_bam_xl330_processed_is_on_no_grid_and_raw_is_on_4096(tmp_path):
    """BAM's processed log is its own linear interpolation onto a 5 ms grid: most readings
    lie between encoder levels, so no step is found (the fit estimates the noise), and the
    note says why. The raw logs (the servo's readings at their own times) are on the
    XL330's 4096-count grid."""
    path = BAM / "bam_xl330_drop_processed.csv"
    _need(path)
    log = read_log(path)
    assert log.resolution is None and log.resolution_note
    raw = sorted((BAM / "raw").glob("*.json"))
    if not raw:
        pytest.skip(f"no raw logs in {BAM / 'raw'}")
    rows = []
    for f in raw:
        d = json.loads(f.read_text())
        if d.get("trajectory") != "lift_and_drop":
            continue
        for e in d["entries"]:
            rows.append((e["timestamp"], e["position"], f.stem))
    assert rows
    frame = pd.DataFrame(rows, columns=["time", "theta", "run"])
    frame.to_csv(tmp_path / "bam_raw.csv", index=False, float_format="%.10g")
    log = read_log(tmp_path / "bam_raw.csv")
    assert log.resolution == pytest.approx(2 * math.pi / 4096, rel=1e-6)
