"""What the benchmark and calibration scripts share: paths, the machine and load record,
and the results files (``results/<name>.json`` and the markdown rendered from it)."""

import datetime
import hashlib
import json
import os
import platform
import resource
import statistics
import subprocess
import time
from pathlib import Path

import hdid

# Benchmarks call hdid's internals and measure the process the CLI sets up: float64,
# the compilation cache, equinox's checks as NaN.
hdid.configure()

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "synthetic"
RESULTS = ROOT / "benchmarks" / "results"


def src_fingerprint() -> str:
    """Hash of src/hdid/**/*.py, recorded with results (src may change between runs)."""
    h = hashlib.sha256()
    for f in sorted((ROOT / "src" / "hdid").rglob("*.py")):
        h.update(str(f.relative_to(ROOT)).encode() + f.read_bytes())
    return h.hexdigest()[:16]


def cpu_model() -> str:
    cpuinfo = Path("/proc/cpuinfo")
    names = [ln.split(":", 1)[1].strip() for ln in (cpuinfo.read_text().splitlines() if cpuinfo.exists() else [])
             if ln.startswith("model name")]
    return names[0] if names else platform.processor() or "?"


def load(tag: str = "") -> dict:
    """The 1/5/15-min load averages and the time, tagged, as the speed results record them."""
    la = os.getloadavg()
    return {"tag": tag, "load1": la[0], "load5": la[1], "load15": la[2],
            "time": datetime.datetime.now().isoformat(timespec="seconds")}


def load_text() -> str:
    """The 1/5/15-min load averages, as the results tables print them."""
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def loads() -> list[float]:
    """The 1/5/15-min load averages, rounded to 0.01, as the posterior results store them."""
    return [round(x, 2) for x in os.getloadavg()]


def machine() -> dict:
    """The speed results' machine record: date, cores, CPU, python, platform, JAX backend and device, package
    versions, the source fingerprint and the 1-min load now."""
    import importlib

    import jax

    dev = jax.devices()[0]
    return {"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "nproc": os.cpu_count(), "cpu": cpu_model(),
            "python": platform.python_version(), "platform": platform.platform(), "backend": jax.default_backend(),
            "device": str(dev), "device_kind": getattr(dev, "device_kind", "?"), "x64": bool(jax.config.jax_enable_x64),
            "src_fingerprint": src_fingerprint(), "load_start": os.getloadavg()[0],
            **{m: importlib.import_module(m).__version__ for m in ("jax", "jaxlib", "numpy", "scipy", "equinox",
                                                                   "optimistix", "hdid")}}


def run_meta(**extra) -> dict:
    """Date, CPU, cores, load and source fingerprint for a results file's header."""
    return {"date": time.strftime("%Y-%m-%d %H:%M"), "cpu": cpu_model(), "cores": os.cpu_count(), "load": load_text(),
            "src": src_fingerprint(), **extra}


class Clock:
    """Wall and process CPU time (user+sys, all threads) of a ``with`` block: ``.wall``, ``.cpu`` [s]."""

    def __enter__(self):
        self.w0, self.c0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.w0
        self.cpu = time.process_time() - self.c0


def user_env(**extra) -> dict:
    """This process's environment as a user's ``hdid`` sees it, with ``extra``: the persistent cache on
    (``HDID_NO_CACHE`` dropped) and Python's compiled modules written and read (``PYTHONDONTWRITEBYTECODE``
    dropped: ``pip install`` compiles them; without them every process compiles hdid's sources, ≈ 1–2 s)."""
    return {k: v for k, v in os.environ.items() if k not in ("HDID_NO_CACHE", "PYTHONDONTWRITEBYTECODE")} | extra


def stats(xs) -> dict:
    """Median, min, max, count and every value of ``xs``."""
    xs = [float(x) for x in xs]
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs), "n": len(xs), "all": xs}


def run_timed(cmd, env=None, timeout=None, cwd=ROOT) -> tuple[float, float, str]:
    """Run ``cmd``: its wall and CPU time (user + sys, all threads) [s] and its stdout; a failure raises
    ``RuntimeError`` with the command and the tails of its output."""
    ru0, t = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    p = subprocess.run([str(c) for c in cmd], env=env, capture_output=True, text=True, cwd=cwd, timeout=timeout)
    wall, ru = time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd[:4]))} failed (rc {p.returncode}):\n{p.stdout[-3000:]}\n"
                           f"{p.stderr[-3000:]}")
    return wall, ru.ru_utime + ru.ru_stime - ru0.ru_utime - ru0.ru_stime, p.stdout


def last_json(stdout: str):
    """The JSON a child process printed as its last line."""
    return json.loads(stdout.strip().splitlines()[-1])


def stored(name: str) -> dict:
    """``results/<name>.json`` as stored, or ``{}``."""
    f = RESULTS / f"{name}.json"
    return json.loads(f.read_text()) if f.exists() else {}


def write_result(name: str, res, render, indent: int = 2) -> None:
    """Store ``results/<name>.json`` and the markdown ``render(res)`` beside it (called after
    every row by the long benchmarks, so a run that is stopped keeps what it measured)."""
    (RESULTS / f"{name}.json").write_text(json.dumps(res, indent=indent, default=str) + "\n")
    (RESULTS / f"{name}.md").write_text(render(res))


def parse_or_render(ap, argv, name, render, indent: int = 2):
    """Parse ``argv`` with ``--render`` (re-write ``results/<name>.md`` from its JSON) and ``--interpretation FILE``
    (markdown stored in the JSON as its Interpretation) added: the arguments, or ``None`` after a render. ``name``
    may be a callable of the arguments (an ``--out`` option)."""
    ap.add_argument("--render", action="store_true",
                    help="re-write the markdown from the stored JSON instead of running")
    ap.add_argument("--interpretation", metavar="FILE",
                    help="with --render: markdown stored in the JSON as its Interpretation")
    args = ap.parse_args(argv)
    if not args.render:
        return args
    name = name(args) if callable(name) else name
    res = json.loads((RESULTS / f"{name}.json").read_text())
    if args.interpretation:
        res["interpretation"] = Path(args.interpretation).read_text().rstrip("\n")
        write_result(name, res, render, indent)
    (RESULTS / f"{name}.md").write_text(render(res))
    return None


def header(*cols: str) -> list[str]:
    """A markdown table's header row and rule: ``| a | b |``, ``|---|---|``."""
    return ["| " + " | ".join(cols) + " |", "|---" * len(cols) + "|"]


def interpretation_section(res: dict) -> list[str]:
    """Markdown lines of the hand-written interpretation stored in ``res``, if any."""
    return ["## Interpretation", "", res["interpretation"], ""] if res.get("interpretation") else []

