#!/bin/bash
# Device entry point (lead): HB's SBC shards on CPU cores 2-15 and HD's GPU batch on the GPU + cores 0-1, together.
# Usage on the device: bash benchmarks/device/run.sh   (OUT set by the tool)
set -u
cd "$(dirname "$0")/../.."
export PYTHONUNBUFFERED=1
T0=$(date +%s)
# a plain `python` where the image has only python3
command -v python >/dev/null || { mkdir -p /tmp/bin; ln -sf "$(command -v python3)" /tmp/bin/python; export PATH=/tmp/bin:$PATH; }
{ nproc; uptime; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv; python3 -V;
  python3 -c "import jax; print(jax.__version__, jax.devices())"; lscpu | grep -E 'Model name|^CPU\(s\)'; } > $OUT/machine.txt 2>&1
( [ -f benchmarks/device/sbc.sh ] && bash benchmarks/device/sbc.sh > $OUT/sbc.log 2>&1 ) &
P1=$!
( [ -f benchmarks/device/gpu.sh ] && bash benchmarks/device/gpu.sh > $OUT/gpu_stdout.log 2>&1 ) &
P2=$!
# uptime every 30 s beside the timings
( while true; do echo "$(( $(date +%s) - T0 )) s: $(uptime)"; sleep 30; done ) > $OUT/load.txt 2>&1 &
P3=$!
wait $P1 $P2
kill $P3 2>/dev/null
echo "total $(( $(date +%s) - T0 )) s" >> $OUT/machine.txt
# at most 8 files come back: pack everything when there are more
n=$(find $OUT -type f | wc -l)
if [ "$n" -gt 7 ] || [ -n "$(find $OUT -mindepth 2 -type f)" ]; then
  tar czf /tmp/all.tar.gz -C $OUT . && find $OUT -mindepth 1 -delete && mv /tmp/all.tar.gz $OUT/ && cp /dev/null $OUT/PACKED
fi
ls -la $OUT
