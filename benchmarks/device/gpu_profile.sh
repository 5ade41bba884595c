#!/usr/bin/env bash
# Issue 37 item 5: where the GPU time of fit_many(lanes="logs") goes (benchmarks/device/gpu_profile.py:
# per-call times of every lane program in fit_many of 100 and up to 1000 logs, a replay of the widest
# solve call at 1/4 iterations and at smaller widths, a jax.profiler trace summarised on the machine).
# Nothing beside it. Whole script about LIMIT seconds (default 190, the cold compile included); the JSON
# is rewritten after every step, so a cut run keeps what it measured.
# Lead: run(command="bash benchmarks/device/gpu_profile.sh", carry=[".whl"], timeout_s=230)
# Results in $OUT: env.txt, profile.json, profile.log, load.txt (4 files).
# Tiny test on a CPU: JAX_PLATFORMS=cpu DISTINCT=4 SIZES="3 6" WIDTHS="8 16" LIMIT=400 bash benchmarks/device/gpu_profile.sh
set -u
cd "$(dirname "$0")/../.."
T0=$SECONDS
OUT=${OUT:-/tmp/hd-prof}; mkdir -p "$OUT"
LIMIT=${LIMIT:-190}
DISTINCT=${DISTINCT:-200}
SIZES=${SIZES:-100 1000}
WIDTHS=${WIDTHS:-1024 4096}
PKL=${PKL:-/tmp/hd_prof_logs.pkl}
export PYTHONPATH="$PWD/src:$PWD/benchmarks${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONUNBUFFERED=1
command -v python >/dev/null || { mkdir -p /tmp/bin; ln -sf "$(command -v python3)" /tmp/bin/python; export PATH=/tmp/bin:$PATH; }
if ! python -c "import emcee, arviz, platformdirs, click" 2>/dev/null && [ -d .whl ]; then
  python -m pip install -q --no-index --find-links .whl .whl/*.whl > "$OUT/env.txt" 2>&1
fi
( while true; do echo "$((SECONDS - T0)) s: $(uptime)"; sleep 20; done ) > "$OUT/load.txt" 2>&1 &
L=$!
{
  date -u; uptime; nproc; python --version
  nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv 2>&1 | head -3
  python -c "import jax; print('jax', jax.__version__, jax.devices())" 2>&1 | tail -1
  git log -1 --oneline 2>/dev/null; git status --short 2>/dev/null | head -20
} >> "$OUT/env.txt" 2>&1
timeout 90 python benchmarks/gpu_path.py --make-logs "$PKL" --distinct "$DISTINCT" --procs 8 >> "$OUT/env.txt" 2>&1
echo "make logs rc $? at $((SECONDS - T0)) s" >> "$OUT/env.txt"
left=$((LIMIT - (SECONDS - T0)))
timeout $((left + 20)) python benchmarks/device/gpu_profile.py --logs "$PKL" --out "$OUT/profile.json" \
  --sizes $SIZES --widths $WIDTHS --budget-s $((left - 10)) --trace-dir /tmp/hd_trace > "$OUT/profile.log" 2>&1
echo "profile rc $? at $((SECONDS - T0)) s" >> "$OUT/env.txt"
kill $L 2>/dev/null
uptime >> "$OUT/env.txt"; ls -la "$OUT" >> "$OUT/env.txt"
