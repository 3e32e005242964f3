import re, sys
exec(open('count.py').read().split('print("vf", count("vf"))')[0])
import pacjax._dynamics.equations as E
from pacjax._model.hessian import _linearise, _on_load_rows
from pacjax._model.kinematics import contract
from pacjax._config import MATMUL_PRECISION
def sforces(self, q, qdot, u, udot, mass):
    sc = self.scene
    consts = sc.constants(q.dtype); coords = sc.coordinates(q); n, d = coords.shape
    plan = sc.energy_plan()
    lin = _linearise(sc, coords, plan, consts, q.dtype)
    parts_jac = lin.jacobians[3]
    rates = jnp.einsum("imd,id->m", parts_jac, sc.coordinates(qdot))
    springs = self._spring_controls(rates, u, udot)
    g_el = jax.grad(lambda x: sc.coords_elastic_energy(x.reshape(n, d), consts))(coords.reshape(-1))
    row_plan = plan.on_load_rows()
    seg_val, seg_jac = _on_load_rows(plan, lin.values), _on_load_rows(plan, lin.jacobians)
    lam_seg, _ = jax.grad(lambda local: sc.load_energy(local, springs, row_plan, consts))((seg_val, lin.traced_values))
    g = jax.vmap(contract)(lam_seg, seg_jac)
    force = -(g_el + g.reshape(-1))
    free = sc.free_coordinates()
    if free is not None: force = force[free]
    force = force - self.damping.stiffness * self.material_damping(q, qdot)
    return force - self.damping.mass * jnp.matmul(mass, qdot, precision=MATMUL_PRECISION)
q = jnp.asarray(start.q); v = jnp.asarray(0.1 * rng.standard_normal(n))
a = model.forces(q, v, u0, jnp.zeros(9), jnp.eye(n))
of = E.EquationsOfMotion.forces
print("vf", count("vf"))
E.EquationsOfMotion.forces = sforces
b = model.forces(q, v, u0, jnp.zeros(9), jnp.eye(n))
print("diff", float(jnp.max(jnp.abs(a - b))), float(jnp.max(jnp.abs(a))))
print("vf with structured forces", count("vf"))
E.EquationsOfMotion.forces = lambda self, q, qdot, u, udot, mass: q + qdot
print("vf without forces", count("vf"))
