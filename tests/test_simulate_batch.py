"""``pj.simulate_batch``: rows one at a time or in vectorised groups, each equal to its own
simulation."""

import jax.numpy as jnp
import numpy as np
import pytest
from dynamics_scenes import small_scene

import pacjax as pj

#: The smallest scene with every force of the dynamics (one compilation of each program).
SCENE = small_scene(order=0, quadrature_points=2)

COMMANDS = np.array([[0.008, 0.002], [0.0, 0.006], [0.004, 0.0]])


@pytest.mark.long(minutes=1.2)
@pytest.mark.slow  # two programs of the dynamics to compile (1 min on 2 cores)
def test_rows_equal_their_own_simulations():
    kwargs = dict(saveat=[0.01, 0.02], solver=pj.dynamics.rosenbrock23(), rtol=1e-6, atol=1e-8)
    q0 = np.zeros((3, SCENE.n_dofs))
    q0[1, 0] = 0.3  # one row starts bent
    batch = pj.simulate_batch(SCENE, (0.0, 0.02), COMMANDS, q0, **kwargs)
    assert batch.q.shape == (3, 2, SCENE.n_dofs) and batch.successful.shape == (3,)
    assert bool(jnp.all(batch.successful))
    for i in range(3):
        single = pj.simulate(SCENE, (0.0, 0.02), COMMANDS[i], q0[i], **kwargs)
        np.testing.assert_allclose(batch.q[i], single.q, rtol=0, atol=1e-12)
        assert int(batch.num_steps[i]) == int(single.num_steps)
    # Rows with different commands take their own steps.
    assert len(set(np.asarray(batch.num_steps).tolist())) > 1
    # As one vectorised group (an accelerator's default) each row accepts and rejects its own
    # steps; the rows make their held Jacobians together, so a row's steps differ a little from
    # its own simulation's, and its states agree to the solver's tolerance (rtol 1e-6).
    group = pj.simulate_batch(SCENE, (0.0, 0.02), COMMANDS, q0, rows_at_once=3, **kwargs)
    assert bool(jnp.all(group.successful))
    np.testing.assert_allclose(group.q, batch.q, rtol=1e-5, atol=1e-7)
    steps, own = np.asarray(group.num_steps), np.asarray(batch.num_steps)
    assert np.all(np.abs(steps - own) <= 0.2 * own), (steps, own)


def test_batch_arguments_are_checked_before_compiling():
    with pytest.raises(ValueError, match="one row per simulation"):
        pj.simulate_batch(SCENE, (0.0, 0.01), COMMANDS[0])
    with pytest.raises(ValueError, match="disagree on the batch size"):
        pj.simulate_batch(SCENE, (0.0, 0.01), COMMANDS, np.zeros((2, SCENE.n_dofs)))
    with pytest.raises(ValueError, match="t_span"):
        pj.simulate_batch(SCENE, (0.1, 0.0), COMMANDS)
    bad = COMMANDS.copy()
    bad[2, 0] = np.nan
    with pytest.raises(ValueError, match=r"controls\[2\]"):
        pj.simulate_batch(SCENE, (0.0, 0.01), bad)
    with pytest.raises(ValueError, match="devices"):
        pj.simulate_batch(SCENE, (0.0, 0.01), COMMANDS, devices=99)
    with pytest.raises(ValueError, match="rows_at_once"):
        pj.simulate_batch(SCENE, (0.0, 0.01), COMMANDS, rows_at_once=0)
    with pytest.raises(TypeError, match="rows_at_once"):
        pj.simulate_batch(SCENE, (0.0, 0.01), COMMANDS, rows_at_once=2.5)


def test_rows_side_by_side_take_a_thread_a_core(monkeypatch):
    """On a CPU the rows run in as many threads as the process has cores (each row's kernels
    run on one thread), never more threads than rows."""
    from pacjax._dynamics import batch

    monkeypatch.setattr(batch.os, "sched_getaffinity", lambda pid: {0, 2, 5}, raising=False)
    assert batch.cpu_lanes() == 3
    workers = []
    real = batch.ThreadPoolExecutor

    def spy(max_workers):
        workers.append(max_workers)
        return real(max_workers=max_workers)

    monkeypatch.setattr(batch, "ThreadPoolExecutor", spy)
    monkeypatch.setattr(batch, "_one_row", lambda *args: jnp.zeros(2))
    args = (SCENE, None, None, (np.zeros((5, 2)), np.zeros((5, 3))), None, None, None, None)
    out = batch._rows_side_by_side(*args, rows=5)
    assert out.shape == (5, 2) and workers == [3]
    batch._rows_side_by_side(*args, rows=2)
    assert workers == [3, 2]
    monkeypatch.delattr(batch.os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(batch.os, "cpu_count", lambda: 6)
    assert batch.cpu_lanes() == 6
