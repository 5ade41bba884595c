"""The rival test's scale against two alternatives, on the linearised fits that
``diagnose_rival_calibration.py`` saves per simulated log (``HDID_RIVAL_SAVE=DIR``; issue 19,
branch ``diag9``): the shipped one (one grid phase for the whole log, 64 midpoints),
an independent phase per set-up, and that plus each run's sub-sample release instant
(the rounding errors of the trajectory shifted by ``δ·dŷ/dk``, ``δ ~ U(−½, ½)`` samples,
the shift itself taken as absorbed by the fitted release instant). Prints, per plant and
true form, the z-score of ``D`` under the truth (mean, sd, max, share beyond ±2) and the
median ``2·ln LR`` for the truth with each scale.

    taskset -c 1 python benchmarks/diagnose_rival_scales.py DIR
"""
import glob, json, math, sys
import numpy as np

from hdid._diagnosis._rival import Linear, cross_evidence, MIN_SD, OUTSIDE
from hdid._diagnosis._floor import saw

def load(f):
    z = np.load(f)
    lins = {}
    for k in "ab":
        lins[k] = Linear(z[f"{k}_r"], z[f"{k}_U"], z[f"{k}_rows"], z[f"{k}_w"], float(z[f"{k}_sigma"]),
                         z[f"{k}_yhat"], float(z[f"{k}_cost"]))
    return lins, tuple(z["shape"]), np.asarray(z["setup_index"]), float(z["d"])

def errors(lin, truth, shape, setup_index, K, rng, jitter=True):
    R, S = shape
    step = lin.sigma * math.sqrt(12.0)
    run = lin.rows // S
    g = np.zeros_like(truth)
    for r_ in np.unique(run):
        m = run == r_
        if m.sum() > 1:
            g[m] = np.gradient(truth[m])   # displacement per sample period
    c = rng.uniform(0, step, size=(K, int(setup_index.max()) + 1))[:, setup_index[run]]
    d = rng.uniform(-0.5, 0.5, size=(K, R))[:, run] if jitter else 0.0
    return saw(truth[None, :] + c + d * g[None, :], step)

def chi2(lin, truth, E):
    Rm = np.repeat(lin.r[None, :], E.shape[0], axis=0)
    Rm[:, lin.rows] = lin.w[None, :] * (lin.yhat[None, :] - truth[None, :] + E) / lin.sigma
    left = Rm - (Rm @ lin.U) @ lin.U.T
    return np.sum(left**2, axis=1)

def evid(a, b, shape, si, K=256, jitter=True, seed=0):
    rng = np.random.default_rng(seed)
    st = []
    for truth in (a.yhat, b.yhat):
        E = errors(a, truth, shape, si, K, rng, jitter)
        D = chi2(b, truth, E) - chi2(a, truth, E)
        st.append((float(np.mean(D)), max(float(np.std(D)), MIN_SD)))
    d = b.cost - a.cost
    (ma, sa), (mb, sb) = st
    za, zb = (d - ma) / sa, (d - mb) / sb
    lr = 0.0 if min(abs(za), abs(zb)) > OUTSIDE else (-za**2 - 2*math.log(sa)) - (-zb**2 - 2*math.log(sb))
    return dict(d=d, ma=ma, sa=sa, mb=mb, sb=sb, lr=lr)

rows = []
for f in sorted(glob.glob(sys.argv[1] + "/*.npz")):
    name = f.split("/")[-1][:-4]
    parts = name.split("_")
    if parts[1] == "ref":
        continue
    plant, seed, truth = parts[0], parts[1], "_".join(parts[2:])
    lins, shape, si, d = load(f)
    a, b = lins["a"], lins["b"]
    ev = cross_evidence(a, b)
    out = {"plant": plant, "seed": seed, "truth": truth}
    for tag, e in (("phase", dict(d=ev.d, ma=ev.mean_a, sa=ev.sd_a, mb=ev.mean_b, sb=ev.sd_b, lr=ev.two_ln_lr)),
                   ("phase_setup", evid(a, b, shape, si, jitter=False)),
                   ("jitter", evid(a, b, shape, si, jitter=True))):
        out[tag] = e
    rows.append(out)

# per plant, per truth: z under the true form; which form is "a"
A = {"8905": "ripple", "9905": "ripple", "8901": "backlash", "8805": "ripple"}
print("plant truth n | scale: mean z, sd z, max|z|, frac |z|>2 | median 2lnLR for truth")
for plant in sorted({r["plant"] for r in rows}):
    for truth in sorted({r["truth"] for r in rows if r["plant"] == plant}):
        sel = [r for r in rows if r["plant"] == plant and r["truth"] == truth]
        line = f"{plant} {truth:20s} {len(sel):2d} |"
        for tag in ("phase", "phase_setup", "jitter"):
            isa = truth == A[plant]
            z = np.array([(r[tag]["d"] - (r[tag]["ma"] if isa else r[tag]["mb"])) / (r[tag]["sa"] if isa else r[tag]["sb"]) for r in sel])
            lr = np.array([r[tag]["lr"] * (1 if isa else -1) for r in sel])
            line += f" {tag}: {z.mean():+.2f} {z.std(ddof=1) if len(z)>1 else float('nan'):.2f} {np.abs(z).max():.1f} {np.mean(np.abs(z)>2):.2f} lr {np.median(lr):+.1f} |"
        print(line)
for tag in ("phase", "phase_setup", "jitter"):
    zz = []
    for r in rows:
        e = r[tag]
        isa = r["truth"] == A[r["plant"]]
        zz.append((e["d"] - (e["ma"] if isa else e["mb"])) / (e["sa"] if isa else e["sb"]))
    zz = np.array(zz)
    print(f"pooled {tag}: {len(zz)} logs, z mean {zz.mean():+.2f} sd {zz.std(ddof=1):.2f}, "
          f"beyond ±2 {np.mean(np.abs(zz) > 2):.1%}")
