"""False-alarm rates of :func:`hdid.diagnose` on clean logs, per design — GENERATED
by ``python benchmarks/diagnose_calibration.py --measured`` from
``benchmarks/results/diagnose_calibration.json``; do not edit (read by
:mod:`hdid._diagnose_rates`)."""

ROWS = (
    {'design': 'paper', 'rate_hz': 250.0, 'runs': 4, 'alarms': 1, 'logs': 96, 'lo': 0.0003, 'hi': 0.0567, 'measured': 'measured 2026-11-24, src 4dda7eb49ff9b674'},
    {'design': 'rich', 'rate_hz': 1000.0, 'runs': 8, 'alarms': 0, 'logs': 46, 'lo': 0.0, 'hi': 0.0771, 'measured': 'measured 2026-11-24, src ad757e93410f3c84'},
)
