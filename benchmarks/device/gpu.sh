#!/usr/bin/env bash
# Issue 37 item 5 (helper HD): fit_many with logs as lanes on the GPU vs one start a call on
# the CPU, by batch size, on one machine. Run from the repository root on the device machine
# (run from the repository root). Whole script under LIMIT seconds (default 440,
# compiles included); each process writes its JSON after every row, so a cut run keeps its rows.
# Results in $OUT: env.txt, gpu.json, gpu.log, cpu.json, cpu.log (5 files; OUT=$OUT/hd for a subfolder).
# Lead: run(command="bash benchmarks/device/gpu.sh", carry=[".whl"] (the wheels; the scripts are tracked), timeout_s=480) — about 7.5 min;
# then put $OUT's files under /tmp/hdid/device/ and touch /tmp/hdid/device/READY.
# Tiny test on a CPU (done here, 2 min): DISTINCT=4 GPU_SIZES="3 6" CPU_SIZES="3" LIMIT=300 bash benchmarks/device/gpu.sh
set -u
T0=$SECONDS
OUT=${OUT:-/tmp/hd-out}; mkdir -p "$OUT"
LIMIT=${LIMIT:-440}
DISTINCT=${DISTINCT:-200}
GPU_SIZES=${GPU_SIZES:-100 1000 10000}
CPU_SIZES=${CPU_SIZES:-100 1000}
GCORE=${GCORE:-0}; CCORE=${CCORE:-1}
WIDTH=${WIDTH:+--width $WIDTH}
PKL=${PKL:-/tmp/hd_logs.pkl}
export PYTHONPATH="$PWD/src:$PWD/benchmarks${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONUNBUFFERED=1
{
  date -u; uptime; nproc; python --version
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | head -3
  python -c "import jax; print('jax', jax.__version__, jax.devices())" 2>&1 | tail -1
  git log -1 --oneline 2>/dev/null; git status --short 2>/dev/null | head -20
} > "$OUT/env.txt" 2>&1

# 1. distinct paper logs (hdid.reference.logs via batch_speed's truths and seeds), cores GCORE,CCORE
timeout 90 taskset -c "$GCORE,$CCORE" python benchmarks/gpu_path.py --make-logs "$PKL" \
  --distinct "$DISTINCT" --procs 2 >> "$OUT/env.txt" 2>&1
echo "make logs rc $? at $((SECONDS - T0)) s" >> "$OUT/env.txt"
[ -s "$PKL" ] || { echo "no logs made" >> "$OUT/env.txt"; exit 1; }

# 2. at once: the GPU process (host work on core GCORE) and the CPU process
#    (JAX_PLATFORMS=cpu, core CCORE); budgets leave room for the last row's overrun
left=$((LIMIT - (SECONDS - T0)))
budget=$((left - 60))
HDID_CACHE_DIR=/tmp/hd_cache_gpu timeout $((left - 5)) taskset -c "$GCORE" \
  python benchmarks/gpu_path.py --crossover "$PKL" --modes logs --sizes $GPU_SIZES \
  --budget-s "$budget" $WIDTH --out "$OUT/gpu.json" > "$OUT/gpu.log" 2>&1 &
G=$!
JAX_PLATFORMS=cpu HDID_CACHE_DIR=/tmp/hd_cache_cpu timeout $((left - 5)) taskset -c "$CCORE" \
  python benchmarks/gpu_path.py --crossover "$PKL" --modes one logs --sizes $CPU_SIZES \
  --budget-s "$budget" --out "$OUT/cpu.json" > "$OUT/cpu.log" 2>&1 &
C=$!
wait $G; echo "gpu rc $? at $((SECONDS - T0)) s" >> "$OUT/env.txt"
wait $C; echo "cpu rc $? at $((SECONDS - T0)) s" >> "$OUT/env.txt"
uptime >> "$OUT/env.txt"
ls -la "$OUT" >> "$OUT/env.txt"
