"""The 40 mm step (PAC, rtol 1e-4) with another step-size controller or error order:
steps, accepted steps, tip error against the rtol-1e-7 reference, warm time (noisy)."""
import functools, json, os, sys, time
import numpy as np, jax, diffrax
import pacjax as pj
from pacjax._dynamics import rosenbrock as R

kw = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
order = kw.pop("error_order", None)
vel = kw.pop("velocity_weight", None)
if vel is not None:
    from pacjax._dynamics import equations as E, simulate as S
    base = E.plane_angle_weights
    def weights(y, args):
        wq, wv = base(y, args)
        return wq, vel * wv
    S.plane_angle_weights = weights
if order is not None:
    R.Rosenbrock23.error_order = lambda self, terms: order
if kw:
    orig = diffrax.PIDController
    diffrax.PIDController = functools.partial(orig, **kw)
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
ts = np.linspace(0, 0.5, 11)
cmds = [np.array([0.04] + [0.0] * 8)]
sys.path.insert(0, "/work/main/benchmarks")
from bench_dynamics import _batch_commands
cmds += list(_batch_commands(64)[:6])
ref = np.load(os.path.join(os.path.dirname(os.path.abspath(__file__)), "ref_tips.npy"))
out = []
for i, u in enumerate(cmds):
    run = lambda: pj.simulate(scene, (0.0, 0.5), u, q0=start.q, saveat=ts, damping=damping, rtol=1e-4)
    tr = jax.block_until_ready(run())
    t = time.perf_counter(); jax.block_until_ready(run()); w = time.perf_counter() - t
    row = dict(steps=int(tr.num_steps), acc=int(tr.num_accepted_steps), warm=round(w, 3))
    if i == 0:
        tips = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
        row["tip_mm"] = round(float(np.max(np.linalg.norm(tips - ref, axis=1)) * 1e3), 4)
    out.append(row)
print(json.dumps(dict(variant=sys.argv[1:], step40=out[0], rows_steps=[r["steps"] for r in out[1:]], rows_acc=[r["acc"] for r in out[1:]], total=sum(r["steps"] for r in out))), flush=True)
