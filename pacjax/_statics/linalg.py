"""Small dense linear algebra of the solver loop, batched in calls that LAPACK runs inline.

On XLA:CPU, ``jnp.linalg.eigh`` and ``jnp.linalg.solve`` of a batch are one LAPACK custom call.
jaxlib 0.10's kernels (``jaxlib/cpu/lapack_kernels.cc``, ``ParallelBatchMap``) split a batch
whose estimated work exceeds ``kMinWorkPerTask`` (2e5 flop-units) into tasks on XLA's intra-op
thread pool and block until they finish. A thread blocked that way holds a pool thread; when as
many such calls run at once as the pool has threads, every thread waits for tasks that no thread
is left to run, and the program hangs. Two ways to get there with pacjax: a step with two
independent solves, and ``pj.solve_batch`` sharded over several CPU devices
(``--xla_force_host_platform_device_count``), whose devices factorise their slots at the same
time (in a debugger: every pool thread in
``EigenvalueDecompositionSymmetricKernel -> ParallelBatchMap -> BlockingCounter::Wait``).

The functions here give the same results, but under ``vmap`` on a CPU they split the batch into
groups small enough for the kernel to run inline, in the calling thread, one group after the
other (``lax.map``). For the matrices of the solver (12 x 12 for the paper's robot with PAC)
that is groups of 8; the whole eigen-decomposition is a few percent of a solver step, and a
group runs at the same speed per matrix as the full batch. Other backends get the plain batched
call.

The batch is laid out as ``(group, call)`` with the rows of a call taken ``groups`` apart, so a
batch sharded in blocks over devices stays sharded along the call axis: each device runs its
own rows' calls.
"""

import math

import jax
import jax.numpy as jnp
import jax.tree_util as jtu

#: jaxlib's ``kMinWorkPerTask``: a batched LAPACK call whose work estimate stays below it runs
#: inline.
_INLINE_WORK = 200_000
#: Upper bound on jaxlib's work estimate per matrix, in units of ``n^3`` (LU: 1, QR: 2, SVD:
#: 10).
_WORK_PER_CUBE = 10


def inline_group(n: int, per_problem: int = 1) -> int:
    """Problems per LAPACK call that the kernel runs inline, each ``per_problem`` matrices of
    size ``n``: a power of two (a batch sharded in blocks over 2, 4, ... devices splits evenly),
    at least 1 (a call of one matrix never goes to the thread pool)."""
    fits = (_INLINE_WORK - 1) // (_WORK_PER_CUBE * per_problem * n**3)
    return 1 << max(0, fits.bit_length() - 1) if fits >= 1 else 1


def _grouped(fn):
    """``fn`` (on one problem; its first argument holds the matrices), whose ``vmap`` calls
    ``fn`` in inline-sized groups on a CPU."""

    @jax.custom_batching.custom_vmap
    def wrapped(*args):
        return fn(*args)

    @wrapped.def_vmap
    def rule(axis_size, in_batched, *args):
        args = [
            a if b else jnp.broadcast_to(a, (axis_size,) + a.shape)
            for a, b in zip(args, in_batched, strict=True)
        ]
        a = args[0]
        group = inline_group(a.shape[-1], math.prod(a.shape[1:-2]))
        batched = jax.vmap(fn)
        if jax.default_backend() != "cpu" or axis_size <= group:
            out = batched(*args)
        else:
            calls = math.ceil(axis_size / group)
            padded = calls * group

            def split(a):
                # Pad with copies of row 0 (a valid problem), then row b = i * calls + j goes
                # to call j, group position i.
                a = jnp.concatenate(
                    [a, jnp.broadcast_to(a[:1], (padded - axis_size,) + a.shape[1:])]
                )
                return jnp.swapaxes(a.reshape((group, calls) + a.shape[1:]), 0, 1)

            def join(a):
                a = jnp.swapaxes(a, 0, 1)
                return a.reshape((padded,) + a.shape[2:])[:axis_size]

            out = jax.lax.map(lambda xs: batched(*xs), tuple(split(a) for a in args))
            out = jtu.tree_map(join, out)
        return out, jtu.tree_map(lambda _: True, out)

    return wrapped


def _one_matrix_per_call(fn):
    """``fn`` on a problem of several matrices (leading axes of every argument), one matrix per
    LAPACK call when together they would exceed the inline budget: a call of one matrix runs
    inline whatever its size, a call of two 100 x 100 systems does not (a 12-segment cubic
    polynomial robot under a follower force: two pool lanes, each factorising its two systems
    on the intra-op pool, hung)."""

    def call(a, *rest):
        lead = a.shape[:-2]
        count = math.prod(lead)
        if (
            count <= 1
            or jax.default_backend() != "cpu"
            or count * _WORK_PER_CUBE * a.shape[-1] ** 3 < _INLINE_WORK
        ):
            return fn(a, *rest)
        flat = [x.reshape((count,) + x.shape[len(lead) :]) for x in (a, *rest)]
        out = jax.lax.map(lambda xs: fn(*xs), tuple(flat))
        return jtu.tree_map(lambda x: x.reshape(lead + x.shape[1:]), out)

    return call


#: ``jnp.linalg.eigh`` of one symmetric matrix; see the module docstring.
eigh = _grouped(_one_matrix_per_call(jnp.linalg.eigh))

#: ``jnp.linalg.solve(a, b)`` of one system (``a`` (..., n, n)); see the module docstring.
solve = _grouped(_one_matrix_per_call(jnp.linalg.solve))
