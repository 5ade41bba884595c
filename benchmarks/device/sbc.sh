#!/bin/bash
# Issue 34 item 4: the posterior calibration (SBC under the default priors), both designs, emcee and SMC on the
# same fits, one process per CPU core (default cores 2-15), JAX on the CPU with one thread each.
# Writes per-shard JSONs (benchmarks/results/posterior_sbc_s<K>.json), per-shard logs, then ONE tarball
# $OUT/sbc.tar.gz. Run from anywhere:  OUT=/some/dir bash benchmarks/device/sbc.sh
# Knobs (environment): CORES ("2 3 ... 15"), WALL (s each shard may run, default 420), PAPER (40), RICH (28),
# SEED0 (36000; rich seeds SEED0+1000...), NOISE (none), MAXSTEPS (20000), EXPECT ("paper:140,rich:150": s a log
# is expected to take before a shard has timed one; a shard starts no log it expects to end after WALL-20 s).
# Merge here afterwards (writes benchmarks/results/posterior_sbc.{json,md}, keeping its cli/checks sections):
#   mkdir -p /tmp/sbc && tar xzf FILES_AT/sbc.tar.gz -C /tmp/sbc
#   python benchmarks/posterior_sbc.py --merge /tmp/sbc/results/posterior_sbc_s*.json
set -u
cd "$(dirname "$0")/../.."
OUT=${OUT:-/tmp/sbc_out}
CORES=${CORES:-"2 3 4 5 6 7 8 9 10 11 12 13 14 15"}
WALL=${WALL:-420}
PAPER=${PAPER:-40}
RICH=${RICH:-28}
SEED0=${SEED0:-36000}
NOISE=${NOISE:-none}
MAXSTEPS=${MAXSTEPS:-20000}
EXPECT=${EXPECT:-paper:140,rich:150}
PY=${PY:-python3}
T0=$(date +%s)
W=$(mktemp -d /tmp/sbc_work.XXXX)
mkdir -p "$OUT" "$W/results" "$W/logs"
rm -f benchmarks/results/posterior_sbc_s*.json benchmarks/results/posterior_sbc_s*.md  # none travelled stale
export PYTHONPATH=$PWD/src PYTHONUNBUFFERED=1 JAX_PLATFORMS=cpu
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NPROC=1
export XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
# no persistent cache on a bare machine: each process compiles cold, into its own scratch cache
if ! $PY -c "import emcee, arviz, platformdirs" 2>/dev/null && [ -d .whl ]; then
  $PY -m pip install -q --no-index --find-links .whl .whl/*.whl >"$W/logs/pip.txt" 2>&1
fi
{ echo "start $(date -u +%FT%TZ)"; uptime; nproc --all; lscpu | grep -E 'Model name|^CPU\(s\)'; $PY -V
  $PY -c "import jax, numpy, scipy, emcee, arviz; print('jax', jax.__version__, 'numpy', numpy.__version__, 'scipy', scipy.__version__, 'emcee', emcee.__version__, 'arviz', arviz.__version__)"
  git rev-parse HEAD 2>/dev/null; git status --short 2>/dev/null | head -30
  echo "CORES=$CORES WALL=$WALL PAPER=$PAPER RICH=$RICH SEED0=$SEED0 NOISE=$NOISE MAXSTEPS=$MAXSTEPS EXPECT=$EXPECT"
} >"$W/logs/machine.txt" 2>&1
( while true; do echo "$(( $(date +%s) - T0 )) s: $(uptime)"; sleep 20; done ) >"$W/logs/load.txt" 2>&1 &
PL=$!
set -- $CORES
N=$#
i=0
PIDS=""
for K in $CORES; do
  PIN="taskset -c $K"; command -v taskset >/dev/null || PIN=""  # unpinned rather than not at all
  HDID_CACHE_DIR=$W/cache$i timeout -k 5 "$WALL" $PIN $PY benchmarks/posterior_sbc.py \
      --paper-logs "$PAPER" --rich-logs "$RICH" --seed0 "$SEED0" --noise "$NOISE" --max-steps "$MAXSTEPS" \
      --paper-first --shard "$i/$N" --end-by $(( WALL - 20 )) --expect-s "$EXPECT" --name "posterior_sbc_s$i" \
      >"$W/logs/s$i.log" 2>&1 &
  PIDS="$PIDS $!"
  i=$((i + 1))
done
for p in $PIDS; do wait "$p"; echo "pid $p rc $?" >>"$W/logs/machine.txt"; done
kill "$PL" 2>/dev/null
cp benchmarks/results/posterior_sbc_s*.json "$W/results/" 2>/dev/null
# what each shard did (a torn JSON from a kill mid-write is reported, not hidden)
$PY - "$W/results" >>"$W/logs/machine.txt" 2>&1 <<'EOF'
import json, sys, pathlib
done = {"paper": 0, "rich": 0}
for f in sorted(pathlib.Path(sys.argv[1]).glob("*.json")):
    try:
        r = json.loads(f.read_text())
    except ValueError as e:
        print(f.name, "TORN", e); continue
    logs = [x for x in r["logs"] if "quantities" in x]
    for x in logs:
        done[x["design"]] += x["method"] == "emcee"
    print(f.name, "logs", len(logs) // 2, "errors", sum("error" in x for x in r["logs"]),
          "skipped", len(r.get("skipped", [])), [(x["design"], x["seed"], x["method"], round(x["total_s"]), round(x.get("cpu_s", 0))) for x in logs])
print("done (emcee rows):", done)
EOF
echo "end $(date -u +%FT%TZ) total $(( $(date +%s) - T0 )) s; $(uptime)" >>"$W/logs/machine.txt"
tar czf "$OUT/sbc.tar.gz" -C "$W" results logs
ls -la "$OUT/sbc.tar.gz"
tail -n 20 "$W/logs/machine.txt"
