import time, sys, jax, jax.numpy as jnp, numpy as np, equinox as eqx
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._dynamics import equations as E
from pacjax._model import inertia as I
from pacjax._dynamics.simulate import prepare
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
damping = pj.Damping.modal(scene)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, I.PHI_INERTIA_FACTOR, None)
model = E.EquationsOfMotion.build(sc, damping, I.PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
q = jnp.zeros(12).at[0].set(0.3).at[4].set(0.2).at[8].set(-0.4).at[2].set(0.5); qd = jnp.ones(12) * 0.1
mode = sys.argv[1]
orig_sa = I._site_accelerations
if mode == "no_acc":
    I._site_accelerations = lambda frames, q, v: (lambda r: (r[1] * v[0], r[1] * v[1], r[1] * 0))(frames(q))
if mode == "const":
    import numpy as onp
    lm = I._knot_masses(model.scene, jnp.float64)
    cm = (onp.asarray(lm.masses), onp.asarray(lm.moments))
    orig_km = I._knot_masses
    I._knot_masses = lambda scene, dtype: I._KnotMasses(orig_km(scene, dtype).knots, jnp.asarray(cm[0]), jnp.asarray(cm[1]))
    ci = onp.asarray(I.coordinate_inertia(model.scene, jnp.float64))
    I.coordinate_inertia = lambda scene, dtype, p=0: jnp.asarray(ci)
if mode == "free_segframes":
    orig_sf = I._segment_frames
    shapes = {}
    def fake(scene, q, knots):
        f = jax.eval_shape(lambda x: orig_sf(scene, x, knots), q)
        c = jnp.sum(q)
        return I._SegmentFrames(*[jnp.ones(x.shape, x.dtype) * c for x in f])
    I._segment_frames = fake
if mode == "no_body":
    E.body_dynamics = lambda s, q, v, p: (jnp.eye(12) * (1 + q[0] ** 2), v * q)
if mode == "no_forces":
    E.EquationsOfMotion.forces = lambda self, q, v, u, ud, m: q * 2 + v
N = 2000
@eqx.filter_jit
def loop(m, q, v):
    def body(i, c):
        q, v = c
        r = m.accelerations(q, v, u, ud)
        return q + 1e-14 * jnp.sum(r), v + 1e-14 * jnp.sum(r)
    return jax.lax.fori_loop(0, N, body, (q, v))
jax.block_until_ready(loop(model, q, qd))
ts = []
for _ in range(7):
    t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); ts.append(time.perf_counter() - t)
print(f"{mode:10s} {np.median(ts)/N*1e6:7.1f} us (min {min(ts)/N*1e6:.1f})")
