"""What importing pacjax sets in JAX (see pacjax/_config.py), and a hang on 2 cores that the
solver must not bring back (independent batched LAPACK calls; see pacjax/_ptc.py)."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax  # noqa: F401


def test_float64_is_on():
    assert jax.config.jax_enable_x64
    assert jnp.zeros(1).dtype == jnp.float64


def test_import_changes_no_other_jax_setting():
    # matmul precision is asked for on each product (pacjax._config.MATMUL_PRECISION), not set
    # for the whole process
    assert jax.config.jax_default_matmul_precision is None


def _equations(jaxpr):
    """Every equation of a jaxpr and of all its sub-jaxprs (loops, conds, calls)."""
    from jax.extend import core as jcore

    for eqn in jaxpr.eqns:
        yield eqn
        for value in eqn.params.values():
            for x in value if isinstance(value, (tuple, list)) else (value,):
                if isinstance(x, jcore.ClosedJaxpr):
                    yield from _equations(x.jaxpr)
                elif isinstance(x, jcore.Jaxpr):
                    yield from _equations(x)


def test_every_product_asks_for_full_precision():
    """JAX's GPU default rounds float32 product inputs to TensorFloat-32 (10-bit mantissa),
    which left 0 % of the paper robot's float32 equilibria converged on an H100: every matrix
    product of a solve, its structured Hessian, and the dynamics' vector field asks for full
    precision."""
    import pacjax as pj
    from pacjax._statics.equilibrium import solve_core
    from pacjax._statics.options import SolverOptions

    scene = pj.presets.stella2023(pj.PAC(), n_sections=1, tip_mass=0.1, quadrature_points=4)
    u, q = jnp.zeros(scene.n_tendons), scene.zeros()
    options = SolverOptions()
    programs = {
        "solve": jax.make_jaxpr(lambda a, b: solve_core(scene, a, b, options))(u, q),
        "dynamics": jax.make_jaxpr(lambda a, b: pj.dynamics.accelerations(scene, a, b, u))(q, q),
    }
    for name, program in programs.items():
        dots = [e for e in _equations(program.jaxpr) if e.primitive.name == "dot_general"]
        assert dots, name
        loose = [e for e in dots if e.params["precision"] != (jax.lax.Precision.HIGHEST,) * 2]
        assert not loose, f"{name}: {len(loose)} of {len(dots)} products at default precision"


def test_float64_can_be_left_off():
    """``PACJAX_NO_X64=1``: importing pacjax leaves JAX in float32, and solves still work."""
    code = textwrap.dedent(
        """
        import jax
        import pacjax as pj
        assert not jax.config.jax_enable_x64
        scene = pj.presets.stella2023(pj.PCC(), n_sections=1, quadrature_points=4)
        eq = pj.solve_equilibrium(scene, tol=1e-4)
        assert eq.q.dtype == jax.numpy.float32 and bool(eq.converged), eq.reason
        """
    )
    env = {**os.environ, "PACJAX_NO_X64": "1"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]


def _lu_calls(jaxpr) -> int:
    """``lu`` equations in a jaxpr and all of its sub-jaxprs (loops, conds, calls)."""
    from jax.extend import core as jcore

    count = 0
    for eqn in jaxpr.eqns:
        count += eqn.primitive.name == "lu"
        for value in eqn.params.values():
            for x in value if isinstance(value, (tuple, list)) else (value,):
                if isinstance(x, jcore.ClosedJaxpr):
                    count += _lu_calls(x.jaxpr)
                elif isinstance(x, jcore.Jaxpr):
                    count += _lu_calls(x)
    return count


def test_non_symmetric_step_factorises_once():
    """The continuation step of a non-conservative scene solves two systems (the shifted flow
    and plain Newton). Two LU custom calls let XLA:CPU run them at once, and jaxlib 0.10's
    batched LAPACK kernels then deadlock on a 2-core machine (both wait on sub-tasks queued to
    the same two-thread pool); the step must factorise both matrices in one call."""
    import pacjax as pj
    from pacjax._statics.equilibrium import solve_core
    from pacjax._statics.options import SolverOptions

    force = pj.PointForce((0.0, 0.0, 1.0), segment=0, s=1.0, follower=True)
    scene = pj.presets.stella2023(pj.PAC(), n_sections=1, loads=(force,), quadrature_points=4)
    u = jnp.zeros((4, scene.n_tendons))
    q = jnp.zeros((4, scene.n_dofs))
    solve = jax.vmap(lambda a, b: solve_core(scene, a, b, SolverOptions()))
    assert _lu_calls(jax.make_jaxpr(solve)(u, q).jaxpr) == 1


def _lapack_batches(hlo: str, target: str) -> list[int]:
    """Matrices in each ``target`` LAPACK custom call of lowered StableHLO text (the product of
    the dimensions before the matrix of its first result)."""
    sizes = []
    for line in hlo.splitlines():
        if target in line and "stablehlo.custom_call" in line:
            result = line.rsplit("->", 1)[1]
            dims = result.split("tensor<", 1)[1].split(">", 1)[0].split("x")
            sizes.append(int(np.prod([int(d) for d in dims[:-3]])))
    return sizes


@pytest.mark.parametrize("batch", [1, 7, 8, 130, 1000])
def test_solver_linear_algebra_runs_in_inline_sized_lapack_calls(batch):
    """Under vmap, the solver's eigh and solve give the plain batched results, but each LAPACK
    call holds at most ``inline_group`` problems, below jaxlib 0.10's threshold for its
    thread-pool path (which hangs when several such calls run at once, see
    pacjax._statics.linalg)."""
    from pacjax._statics import linalg as _linalg

    rng = np.random.default_rng(0)
    a = rng.normal(size=(batch, 12, 12))
    a = a + np.swapaxes(a, 1, 2)
    stacked = np.stack([a, a + 30 * np.eye(12)], axis=1)
    b = rng.normal(size=(batch, 2, 12, 1))
    eigh = jax.jit(jax.vmap(_linalg.eigh))
    solve = jax.jit(jax.vmap(_linalg.solve))
    w, v = eigh(a)
    w_ref, v_ref = jnp.linalg.eigh(a)
    np.testing.assert_allclose(w, w_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.abs(v), np.abs(v_ref), rtol=0, atol=1e-10)
    np.testing.assert_allclose(solve(stacked, b), jnp.linalg.solve(stacked, b), atol=1e-10)
    assert _linalg.inline_group(12) == 8 and _linalg.inline_group(12, 2) == 4
    assert _linalg.inline_group(100) == 1
    for fn, args, target, group in (
        (eigh, (a,), "syevd", 8),
        (solve, (stacked, b), "getrf", 8),  # 4 problems of 2 matrices
    ):
        sizes = _lapack_batches(fn.lower(*args).as_text(), target)
        assert sizes and max(sizes) <= min(group, 2 * batch), sizes


def test_batched_solver_makes_inline_sized_lapack_calls():
    """The vmapped solver of the paper's robot (12 x 12 stiffness) eigen-decomposes a batch of
    32 in calls of at most 8 (one call of 32 took jaxlib 0.10's thread-pool path and hung with
    the pool sharded over two CPU devices)."""
    import pacjax as pj
    from pacjax._statics.equilibrium import solve_core
    from pacjax._statics.options import SolverOptions

    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    u = jnp.zeros((32, scene.n_tendons))
    q = jnp.zeros((32, scene.n_dofs))
    solve = jax.jit(jax.vmap(lambda a, b: solve_core(scene, a, b, SolverOptions())))
    sizes = _lapack_batches(solve.lower(u, q).as_text(), "syevd")
    assert sizes and max(sizes) <= 8, sizes


@pytest.mark.slow
def test_follower_force_batch_does_not_hang():
    """The batched solve of the paper study's follower-force data (seed 0, 16 frames) hung on
    2 cores in 7 of 10 runs: gdb showed every XLA:CPU pool thread inside a batched LU
    (``LuDecompositionKernel -> ParallelBatchMap -> BlockingCounter::Wait``), the flow and the
    Newton systems of one continuation step factorised by two concurrent calls. With one
    factorisation it finished in 59-69 s (6 of 6). A hang fails this test at the subprocess
    timeout instead of stalling the run."""
    code = """
        import numpy as np
        import pacjax as pj
        # the draws of experiments/paper_study/paper_study.py (seed 0, 16 frames) up to its
        # follower-force case
        rng = np.random.default_rng(0)
        cases = [(1, "horizontal", (0.0, 0.5, 1.0)), (1, "hanging", (0.0, 0.5, 1.0)),
                 (3, "hanging", (0.0, 0.2, 0.4)), (3, "hanging", (0.0,))]
        for n_sections, mount, payloads in cases:
            scene = pj.presets.stella2023(pj.PAC(), n_sections=n_sections, mount=mount)
            u = rng.uniform(0.0, 0.025, (16, scene.n_tendons))
            for k in range(0, scene.n_tendons, 3):
                u[np.arange(16), k + rng.integers(0, 3, 16)] = 0.0
            mass = np.asarray(payloads)[rng.integers(0, len(payloads), 16)]
        data, truth = pj.synthetic_mocap(
            scene, u, payload_mass=mass, noise=1e-3, dropout=0.05, orientations=True,
            orientation_noise=0.0, seed=0, force=np.tile([0.0, 0.0, 3.41], (16, 1)),
            force_follower=True,
        )
        print(len(truth.q))
    """
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.split()[-1]) >= 15  # frames whose truth converged
