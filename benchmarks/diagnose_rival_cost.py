"""Where the rival test's time goes in ``hdid.diagnose`` of the shipped 1 kHz hidden-hysteresis
log, in one process (issue 19, branch ``diag9``): ``_refit.residuals_and_jacobian``,
``_rival.linear_of``, ``_rival.cross_evidence`` and ``rank_within_families`` wrapped with
wall and CPU timers, the program store's new programs per diagnose.

    taskset -c 1 python benchmarks/diagnose_rival_cost.py 3     # three diagnoses
"""
import sys, time, os, json
import hdid
hdid.configure()
from hdid._diagnosis import _rival, _diagnose
from hdid._fitting import _refit
from hdid._problems import _programs
LOG = str(__import__("pathlib").Path(__file__).resolve().parents[1] / "data" / "synthetic" / "hidden_hysteresis_1khz.csv")
T = {}
def wrap(mod, name):
    f = getattr(mod, name)
    def g(*a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            return f(*a, **k)
        finally:
            w, c = T.setdefault(name, [0.0, 0.0, 0])[:2]
            T[name] = [w + time.perf_counter() - t0, c + time.process_time() - c0, T[name][2] + 1]
    setattr(mod, name, g)
wrap(_refit, "residuals_and_jacobian")
wrap(_rival, "linear_of")
wrap(_rival, "cross_evidence")
wrap(_diagnose, "rank_within_families")
for i in range(int(sys.argv[1])):
    T.clear(); n0 = len(_programs.STATS)
    t0, c0 = time.perf_counter(), time.process_time()
    d = hdid.diagnose(LOG)
    print(i, "diagnose wall %.2f cpu %.2f" % (time.perf_counter()-t0, time.process_time()-c0),
          "load", os.getloadavg()[0], d.verdict, [(c.label, round(c.delta_bic, 3)) for c in d.candidates[:4]])
    print("  ", {k: [round(v[0], 3), round(v[1], 3), v[2]] for k, v in T.items()})
    print("  new programs", [(s["name"], s["how"]) for s in _programs.STATS[n0:]])
    print("  ", [n[:200] for n in d.notes if "white floor" in n])
