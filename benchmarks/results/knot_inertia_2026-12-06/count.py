import re, sys
exec(open('bw_setup.py').read())
import pacjax._model.inertia as I
def count(kind):
    q = jnp.asarray(np.asarray(start.q)[None]); v = jnp.asarray(0.1 * rng.standard_normal((1, n)))
    txt = jax.jit(jax.vmap(parts(kind))).lower(q, v).compile().as_text()
    body = txt[txt.index("\nENTRY"):]
    body = body[:body.index("\n}")]
    return sum(1 for l in body.splitlines()[1:] if " = " in l and not re.search(r"= \S+ (parameter|bitcast|get-tuple-element|constant|tuple)\(", l))
print("vf", count("vf"))
orig = I._site_accelerations
I._site_accelerations = lambda frames, q, qdot: tuple(jnp.zeros_like(x) for x in (frames(q)[1],) * 3)
print("vf without accelerations", count("vf"))
I._site_accelerations = orig
import pacjax._dynamics.equations as E
ob = E.body_dynamics
E.body_dynamics = lambda scene, q, qdot, phi: (jnp.eye(q.shape[0], dtype=q.dtype) * (1 + q.sum()), q * 0)
print("vf without body", count("vf"))
E.body_dynamics = ob
of = E.EquationsOfMotion.forces
E.EquationsOfMotion.forces = lambda self, q, qdot, u, udot, mass: q + qdot
print("vf without forces", count("vf"))
E.EquationsOfMotion.forces = of
om = E.EquationsOfMotion.material_damping
E.EquationsOfMotion.material_damping = lambda self, q, qdot: qdot
print("vf without material damping", count("vf"))
E.EquationsOfMotion.material_damping = om
