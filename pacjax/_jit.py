"""``jit`` for pacjax's solver programs: ``equinox.filter_jit`` with XLA:CPU compile options
that shorten compilation.

On XLA:CPU (jaxlib 0.10) most of the compile time of the solver's round goes to the MLIR
fusion emitters. The classic elemental emitters compile the same HLO in about half the time
with the same run time for the statics programs (``benchmarks/RESULTS.md``, "Bending-vector
steps, 100x dt growth, classic XLA:CPU emitters"). The dynamics' integration keeps the default
emitters: its long integrations ran slower with the classic ones; the programs a simulation runs
once before it (the start's plane alignment, the default damping's lowest mode) take them.

``PACJAX_FAST_COMPILE=1`` adds LLVM's optimisation level 0 (``xla_backend_optimization_level``)
to them: the statics programs then compile in roughly two thirds of the time and run slower
(``benchmarks/RESULTS.md``, "CI time"), which pays where each program runs a few times (one-off
solves); the dynamics' long integrations keep the default level. The programs that run once
for each call of the function that needs them (``jit(once=True)``: a simulation's start
alignment, a scene's default damping) take level 0 always: the start's alignment compiles in
about half the time and runs in milliseconds either way. Results differ from the default
level's in the last bits, which can decide a float32 solve at its round-off floor.

The options go to CPU compilations only, are left out where ``XLA_FLAGS`` sets them (the
user's choice stands), and are dropped when this jaxlib does not know them (checked once, on a
trivial program, at the first compilation). JAX takes compile options on a top-level ``jit``
only, so a call made while tracing (inside the user's ``jit``, ``grad`` or ``vmap``) compiles
without them, as part of the caller's program.
"""

import functools
import os
import threading

import equinox as eqx
import jax

from ._stored import call_stored

try:
    from jax.extend.core import get_opaque_trace_state
except ImportError:  # an older jax: no options (they need to know that no trace is running)
    get_opaque_trace_state = None


def _state_outside_any_trace():
    """The trace state outside any transformation. Taken in a new thread (trace states are per
    thread), so that it is right even when this module is first imported while a trace runs:
    ``import pacjax`` loads its modules on first use, which may be inside the user's ``jit``."""
    if get_opaque_trace_state is None:
        return None
    state = []
    thread = threading.Thread(target=lambda: state.append(get_opaque_trace_state()))
    thread.start()
    thread.join()
    return state[0]


#: The trace state outside any transformation (taken at import).
_TOP_LEVEL = _state_outside_any_trace()

#: XLA debug options of CPU compilations (see the module docstring).
CPU_COMPILE_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
#: Added with ``PACJAX_FAST_COMPILE=1``: compile time before run time.
FAST_COMPILE_OPTIONS = {"xla_backend_optimization_level": 0}


@functools.cache
def compile_options(backend: str, once: bool = False) -> tuple[tuple[str, object], ...]:
    """The options of :data:`CPU_COMPILE_OPTIONS` (and :data:`FAST_COMPILE_OPTIONS` with
    ``PACJAX_FAST_COMPILE=1`` or for a program that runs ``once``) that apply on ``backend``:
    none off CPU, none that ``XLA_FLAGS`` sets, none if this jax / jaxlib does not accept
    them."""
    if backend != "cpu":
        return ()
    flags = os.environ.get("XLA_FLAGS", "")
    wanted = dict(CPU_COMPILE_OPTIONS)
    if once or os.environ.get("PACJAX_FAST_COMPILE", "") not in ("", "0"):
        wanted.update(FAST_COMPILE_OPTIONS)
    options = {k: v for k, v in wanted.items() if f"--{k}=" not in flags}
    if not options:
        return ()
    try:
        jax.jit(lambda x: x + 1, compiler_options=options).lower(1.0).compile()
    except (TypeError, ValueError, jax.errors.JaxRuntimeError):
        # An older jax.jit without compiler_options, or an XLA without the option.
        return ()
    return tuple(options.items())


def _top_level() -> bool:
    return _TOP_LEVEL is not None and get_opaque_trace_state() == _TOP_LEVEL


def jit(fn=None, *, once: bool = False):
    """``equinox.filter_jit(fn)``; a top-level call compiles with :func:`compile_options` of
    the default backend (decided at the first call, not at import, so that the backend can
    still be chosen after ``import pacjax``). With the compilation cache on, a top-level call
    loads its traced program from disk where an earlier process stored it
    (:mod:`pacjax._stored`).

    ``once``: the program runs once for each call of the function that needs it (a
    simulation's start, a scene's default damping), so its compile time is all it costs: it
    takes :data:`FAST_COMPILE_OPTIONS` whatever ``PACJAX_FAST_COMPILE`` says."""
    if fn is None:
        return functools.partial(jit, once=once)
    plain = eqx.filter_jit(fn)
    lock = threading.Lock()
    jitted = {}

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if not _top_level():
            return plain(*args, **kwargs)
        backend = jax.default_backend()
        options = dict(compile_options(backend, once))
        out = call_stored(fn, options, args, kwargs)
        if out is not NotImplemented:
            return out
        with lock:
            f = jitted.get(backend)
            if f is None:
                f = eqx.filter_jit(fn, compiler_options=options) if options else plain
                jitted[backend] = f
        return f(*args, **kwargs)

    return call
