import sys, numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._statics import ptc
rec = []
orig = ptc.PseudoTransientContinuation._search
def patched(self, fn, y, args, state, delta, took_newton, first, escape):
    alpha, ok = orig(self, fn, y, args, state, delta, took_newton, first, escape)
    jax.debug.callback(lambda a, f: rec.append((np.asarray(a).copy(), np.asarray(f).copy())), alpha, first)
    return alpha, ok
ptc.PseudoTransientContinuation._search = patched
which = sys.argv[1]
if which == "paper":
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2); hi = 0.02
else:
    scene = pj.presets.tentacle(model=pj.PolynomialCurvature(1) if which == "poly1" else pj.PAC()); hi = 2.0
u = np.random.default_rng(0).uniform(0, hi, (1000, scene.n_tendons))
sol = pj.solve_batch(scene, u, chunk_size=1000, fallback=False, progress=False)
a = np.concatenate([x[0].ravel() for x in rec]); f = np.concatenate([x[1].ravel() for x in rec])
print(which, "calls", len(rec), "slot-steps", a.size, "not first", (~f).sum(), "shortened", ((a < 1) & ~f).sum())
short_calls = sum(1 for x in rec if np.any((x[0] < 1) & ~x[1]))
print("pool steps with any shortened slot:", short_calls, "of", len(rec))
