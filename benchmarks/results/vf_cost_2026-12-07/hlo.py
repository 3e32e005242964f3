import re, collections, jax, jax.numpy as jnp, numpy as np, equinox as eqx
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._dynamics.equations import EquationsOfMotion
from pacjax._model.inertia import PHI_INERTIA_FACTOR
from pacjax._dynamics.simulate import prepare
from pacjax._model import inertia as I
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
damping = pj.Damping.modal(scene)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(sc, damping, PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
q = jnp.zeros(12).at[0].set(0.3).at[4].set(0.2); qd = jnp.ones(12) * 0.1
parts = {"accelerations": lambda m, q, v: m.accelerations(q, v, u, ud),
 "body": lambda m, q, v: I.body_dynamics(m.scene, q, v),
 "forces": lambda m, q, v: m.forces(q, v, u, ud, jnp.eye(12)),
}
for name, f in parts.items():
    p, s = eqx.partition(model, eqx.is_array); txt = jax.jit(lambda p, q, v: f(eqx.combine(p, s), q, v)).lower(p, q, qd).compile().as_text()
    entry = txt[txt.index("ENTRY"):]
    ops = collections.Counter(re.findall(r"= \S+ (\w[\w-]*)\(", entry))
    n = sum(ops.values())
    print(name, n, ops.most_common(12))
p, s = eqx.partition(model, eqx.is_array)
txt = jax.jit(lambda p, q, v: eqx.combine(p, s).accelerations(q, v, u, ud)).lower(p, q, qd).compile().as_text()
entry = txt[txt.index("ENTRY"):]
names = re.findall(r"= \S+ fusion\(.*?calls=%?([\w.-]+)", entry)
kinds = collections.Counter(re.sub(r"[._]\d+$", "", re.sub(r"\.\d+$", "", n)) for n in names)
print(kinds.most_common(40))
others = collections.Counter(re.findall(r"= \S+ ((?!fusion)[\w-]+)\(", entry))
print(others)
open("/tmp/s38/vf_hlo.txt", "w").write(txt)
