"""Helpers shared by the benchmark scripts (run them as `python benchmarks/<script>.py`)."""

from __future__ import annotations

import hashlib
import importlib.util
import platform
from pathlib import Path

import hdid

# Benchmarks call hdid's internals and measure the process the CLI sets up: float64,
# the compilation cache, equinox's checks as NaN. (Code from before issue 20 configured
# itself on import and has no ``configure``.)
if hasattr(hdid, "configure"):
    hdid.configure()

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "synthetic"


def src_fingerprint() -> str:
    """Hash of src/hdid/**/*.py, recorded with results (src may change between runs)."""
    h = hashlib.sha256()
    for f in sorted((ROOT / "src" / "hdid").rglob("*.py")):
        h.update(str(f.relative_to(ROOT)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def import_generate():
    """data/synthetic/generate.py as a module (make_log, TRUTH_CSF8, designs)."""
    spec = importlib.util.spec_from_file_location("_hdid_generate", DATA / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def import_scipy_way():
    """benchmarks/scipy_way.py as a module (``fit_scipy``, the fit without hdid)."""
    spec = importlib.util.spec_from_file_location("_hdid_scipy_way", ROOT / "benchmarks" / "scipy_way.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def load(tag: str = "") -> dict:
    """The 1/5/15-min load averages and the time, tagged, as the speed results record them."""
    import datetime
    import os

    la = os.getloadavg()
    return {"tag": tag, "load1": la[0], "load5": la[1], "load15": la[2],
            "time": datetime.datetime.now().isoformat(timespec="seconds")}


def cpu_model() -> str:
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return cpu


RESULTS = ROOT / "benchmarks" / "results"


class Clock:
    """Wall and process CPU time (user+sys, all threads) of a ``with`` block:
    ``.wall`` and ``.cpu`` in seconds."""

    def __enter__(self):
        import time

        self._time = time
        self.w0, self.c0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = self._time.perf_counter() - self.w0
        self.cpu = self._time.process_time() - self.c0


def rerender(name: str, render, interpretation: str | None = None) -> int:
    """Re-write ``results/<name>.md`` from ``results/<name>.json`` (``--render``), first
    storing the text of the file ``interpretation`` in the JSON when given."""
    import json

    out_json = RESULTS / f"{name}.json"
    res = json.loads(out_json.read_text())
    if interpretation:
        res["interpretation"] = Path(interpretation).read_text()
        out_json.write_text(json.dumps(res, indent=2) + "\n")
    (RESULTS / f"{name}.md").write_text(render(res))
    return 0


def result_writer(name: str, render):
    """A ``write(res)`` that stores ``results/<name>.json`` and its markdown (``render``):
    called after every row, so a long benchmark leaves its partial results if stopped;
    ``write(res, row=rec, label=..., tail=...)`` first appends the process row ``rec`` to
    ``res["rows"]`` and prints its wall time and loads; ``write(res, end=True)`` also
    records the load at the end."""
    import json

    def write(res: dict, end: bool = False, row: dict | None = None, label: str = "",
              tail: str = "") -> None:
        if row is not None:
            res["rows"].append(row)
            print(f"{label}: {row.get('process_wall_s', 0):.1f} s (load {row.get('load_start')} "
                  f"→ {row.get('load_end')}){' ' + tail if tail else ''}", flush=True)
        if end:
            res["meta"]["load_end"] = load_text()
        (RESULTS / f"{name}.json").write_text(json.dumps(res, indent=2) + "\n")
        (RESULTS / f"{name}.md").write_text(render(res))

    return write


def interpretation_section(res: dict) -> list[str]:
    """Markdown lines of the hand-written interpretation stored in ``res``, if any."""
    text = res.get("interpretation")
    return ["## Interpretation", "", text, ""] if text else []


def add_render_args(ap) -> None:
    """``--render`` (re-write the markdown from the stored JSON, no run) and
    ``--interpretation FILE`` (hand-written text stored with it), as :func:`rerender` uses."""
    ap.add_argument("--render", action="store_true",
                    help="re-write the markdown from the stored JSON instead of running")
    ap.add_argument("--interpretation", help="markdown file stored as the Interpretation section")


def parse_or_render(ap, argv, name, render):
    """Add the render options, parse ``argv``; with ``--render`` re-write
    ``results/<name>.md`` from its JSON (:func:`rerender`) and return ``None``, else the
    parsed arguments. ``name`` may be a callable of the arguments (an ``--out`` option)."""
    add_render_args(ap)
    args = ap.parse_args(argv)
    if args.render:
        rerender(name(args) if callable(name) else name, render, args.interpretation)
        return None
    return args



def load_text() -> str:
    """The 1/5/15-min load averages, as the results tables print them."""
    import os

    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def run_meta(**extra) -> dict:
    """Date, CPU, cores, load and source fingerprint for a results file's header."""
    import os
    import time

    return {"date": time.strftime("%Y-%m-%d %H:%M"), "cpu": cpu_model(),
            "cores": os.cpu_count(), "load": load_text(), "src": src_fingerprint(), **extra}


def run_designs(designs, run, write, records: list, meta: dict) -> None:
    """``run(k, design)`` for each design, writing the records after each and at the end
    (with the end load): a long benchmark leaves its partial results if stopped."""
    for k, design in enumerate(designs):
        run(k, design)
        write(records, meta)
    meta["load_end"] = load_text()
    write(records, meta)
