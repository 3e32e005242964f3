"""``pj.solve_batch`` sharded over two (virtual CPU) devices agrees with one device;
``pj.simulate_batch`` there runs its rows side by side as on one.

XLA fixes the number of host devices when JAX starts, so the two-device run happens in a fresh
interpreter with ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` set before importing
JAX.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

CODE = r"""
import json, os
import jax
import numpy as np
import pacjax as pj

assert len(jax.devices()) == 2, jax.devices()
# The scene of tests/test_batch.py.
seg = pj.Segment(0.15, 0.05, 2000.0, linear_density=0.3)
tendons = [pj.Tendon(0, a, 0.02, gain=5e3) for a in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)]
scene = pj.Scene(
    pj.Robot([seg]),
    pj.PolynomialCurvature(1),
    tendons=tendons,
    loads=(pj.Gravity(direction=(1.0, 0.0, 0.0)), pj.PointMass(0.1, 0)),
)
commands = np.random.default_rng(0).uniform(0.0, 0.01, (6, 3))
# Record over how many devices the solver pool's state lives, round after round.
import pacjax._statics.pool as pool_module
pool_devices = []
advance = pool_module._advance
def spy(*args):
    out = advance(*args)
    pool_devices.append(len(out[0][2].devices()))  # the slots' iterates
    return out
pool_module._advance = spy
two = pj.solve_batch(scene, commands, chunk_size=4)             # default: every device
two_devices = list(pool_devices)
one = pj.solve_batch(scene, commands, chunk_size=4, devices=1)
rows, first = next(pj.iter_batch(scene, commands, chunk_size=4))
print(json.dumps({
    "n_devices": len(jax.devices()),
    "pool_devices": sorted(set(two_devices)),
    "chunk_rows": rows.stop - rows.start,
    "two": np.asarray(two.q).tolist(),
    "one": np.asarray(one.q).tolist(),
    "converged_two": np.asarray(two.converged).tolist(),
    "converged_one": np.asarray(one.converged).tolist(),
}))
"""


def _on_two_cpu_devices(code: str, timeout: float) -> dict:
    """Run ``code`` in a fresh interpreter with two host devices; its last line, as JSON."""
    env = dict(os.environ)
    env["XLA_FLAGS"] = env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env["JAX_PLATFORMS"] = "cpu"
    # No persistent compilation cache: executables compiled for two host devices must never be
    # read back by the one-device test process (see tests/conftest.py).
    env.pop("PACJAX_CACHE_DIR", None)
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=timeout
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # over a minute of compilation: CI's slow step
def test_solve_batch_on_two_cpu_devices_matches_one_device():
    out = _on_two_cpu_devices(CODE, timeout=900)
    assert out["n_devices"] == 2
    # A pool of 4 slots is split over both devices (2 rows each) in every round.
    assert out["chunk_rows"] == 4 and out["pool_devices"] == [2]
    assert all(out["converged_two"]) and all(out["converged_one"])
    np.testing.assert_allclose(out["two"], out["one"], rtol=0, atol=1e-12)


PAPER_ROBOT = r"""
import json
import jax
import numpy as np
import pacjax as pj
from pacjax.cli.bench import random_commands

assert len(jax.devices()) == 2, jax.devices()
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
commands = random_commands(96)
eq = pj.solve_batch(scene, commands, chunk_size=96, progress=False)
print(json.dumps({"converged": np.asarray(eq.converged).tolist(), "q": np.asarray(eq.q).tolist()}))
"""


@pytest.mark.slow  # two compilations of the paper's robot in a fresh interpreter
def test_paper_robot_sharded_over_two_cpu_devices_does_not_hang():
    """48 slots per device of a 12 x 12 eigen-decomposition: past jaxlib 0.10's threshold for
    its parallel LAPACK path, which hung when both devices took it at once (pacjax._statics.linalg).
    Before the fix this run waited forever at 0 % CPU; now it takes about a minute."""
    out = _on_two_cpu_devices(PAPER_ROBOT, timeout=600)
    assert all(out["converged"])
    import pacjax as pj
    from pacjax.cli.bench import random_commands

    one = pj.solve_batch(pj.presets.stella2023(pj.PAC(), tip_mass=0.2), random_commands(96)[:8])
    np.testing.assert_allclose(np.asarray(out["q"])[:8], np.asarray(one.q), rtol=0, atol=1e-8)


SIMULATE = r"""
import json, sys
import numpy as np
import pacjax as pj
sys.path.insert(0, "tests")
from dynamics_scenes import small_scene
scene = small_scene(order=0, quadrature_points=2)
commands = np.array([[0.008, 0.002], [0.0, 0.006], [0.004, 0.0]])
kwargs = dict(saveat=[0.02], rtol=1e-4, atol=1e-6)  # simulate's default solver
batch = pj.simulate_batch(scene, (0.0, 0.02), commands, **kwargs)
single = [pj.simulate(scene, (0.0, 0.02), u, **kwargs) for u in commands]
print(json.dumps({
    "batch_steps": np.asarray(batch.num_steps).tolist(),
    "single_steps": [int(s.num_steps) for s in single],
    "gap": max(float(np.max(np.abs(np.asarray(batch.q[i]) - np.asarray(s.q))))
               for i, s in enumerate(single)),
}))
"""


@pytest.mark.slow  # the dynamics compiled in a fresh interpreter
def test_simulate_batch_on_two_cpu_devices_runs_rows_side_by_side():
    """On a CPU, host devices share the cores: by default the rows run as on one device, each
    with ``simulate``'s solver and steps, not as one vectorised group over both devices (whose
    rows would make their Jacobians together and run the slowest row's steps)."""
    out = _on_two_cpu_devices(SIMULATE, timeout=600)
    assert out["batch_steps"] == out["single_steps"]
    assert out["gap"] == 0.0
