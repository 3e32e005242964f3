"""Batched solves agree with single solves; chunking and warm starts do not change results."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj


@pytest.fixture(scope="module")
def scene():
    seg = pj.Segment(0.15, 0.05, 2000.0, linear_density=0.3)
    tendons = [pj.Tendon(0, a, 0.02, gain=5e3) for a in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)]
    return pj.Scene(
        pj.Robot([seg]),
        pj.PolynomialCurvature(1),
        tendons=tendons,
        loads=(pj.Gravity(direction=(1.0, 0.0, 0.0)), pj.PointMass(0.1, 0)),
    )


def test_batch_matches_single_solves(scene):
    commands = np.random.default_rng(0).uniform(0.0, 0.01, (5, 3))
    batch = pj.solve_batch(scene, commands, chunk_size=4, warm_start=True)
    assert batch.q.shape == (5, scene.n_dofs)
    assert np.all(batch.converged)
    for i, u in enumerate(commands):
        single = pj.solve_equilibrium(scene, u)
        np.testing.assert_allclose(batch.q[i], single.q, atol=1e-9)


def test_slots_take_rows_as_others_finish_as_single_solves_would(scene, monkeypatch):
    # 12 rows through two pools of 2 slots: a slot takes the next row inside a call as soon as
    # its row is done, and calls cut short by their step cap (2 here) leave their pending rows
    # to the next call. Every row still takes its single solve's iterates, and ends one
    # linearisation sooner where its next step lands within the tolerance (the pool tries each
    # next step ahead; a single solve linearises there to find it converged).
    from pacjax._statics import pool

    calls = []
    round_ = pool._round

    def spy(*args):
        out = round_(*args)
        calls.append((len(args[8][0]), int(out[1])))  # rows pending, rows started
        return out

    monkeypatch.setattr(pool, "MAX_STEPS_PER_CALL", 2)
    monkeypatch.setattr(pool, "_round", spy)
    commands = np.random.default_rng(7).uniform(0.0, 0.012, (12, 3))
    batch = pj.solve_batch(scene, commands, chunk_size=3)
    assert np.all(batch.converged)
    assert any(started < pending for pending, started in calls)
    for i, u in enumerate(commands):
        single = pj.solve_equilibrium(scene, u)
        np.testing.assert_allclose(batch.q[i], single.q, atol=1e-9)
        assert int(single.steps) - 1 <= int(batch.steps[i]) <= int(single.steps)
    ends = [pj.solve_equilibrium(scene, u).steps for u in commands]
    assert np.any(np.asarray(batch.steps) < np.asarray(ends))


def test_batch_over_payloads(scene):
    masses = np.array([0.0, 0.1, 0.3])
    commands = np.zeros((3, 3))
    batch = pj.solve_batch(
        scene,
        commands,
        params=masses,
        update=lambda sc, m: eqx.tree_at(lambda s: s.loads[1].mass, sc, m),
        chunk_size=4,
    )
    tips = [np.asarray(pj.tip_pose(scene, q)[0]) for q in batch.q]
    # Gravity along +x: a heavier payload pulls the tip further along x.
    assert tips[0][0] < tips[1][0] < tips[2][0]


def test_batch_rejects_bad_shapes(scene):
    with pytest.raises(ValueError, match="controls_batch must have shape"):
        pj.solve_batch(scene, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="q0 must have shape"):
        pj.solve_batch(scene, np.zeros((4, 3)), q0=np.zeros((3, scene.n_dofs)))


def test_pool_refills_slots_and_yields_chunks_in_order(scene):
    # Rows of very different difficulty finish at different steps: slots are refilled as rows
    # finish, yet every chunk comes out whole, in order, and equal to single solves.
    rng = np.random.default_rng(3)
    commands = rng.uniform(0.0, 0.012, (7, 3))
    commands[[0, 4]] = 0.0  # straight: done in a couple of steps
    parts = list(pj.iter_batch(scene, commands, chunk_size=3))
    assert [(rows.start, rows.stop) for rows, _ in parts] == [(0, 3), (3, 6), (6, 7)]
    assert all(type(rows.start) is int and type(rows.stop) is int for rows, _ in parts)
    steps = np.concatenate([np.asarray(eq.steps) for _, eq in parts])
    assert steps.min() < steps.max()  # the rows did finish at different rounds
    for rows, eq in parts:
        for i, u in zip(range(rows.start, rows.stop), commands[rows], strict=True):
            single = pj.solve_equilibrium(scene, u)
            np.testing.assert_allclose(eq.q[i - rows.start], single.q, atol=1e-9)
            # (one linearisation fewer where the step tried ahead ends the row)
            assert int(single.steps) - 1 <= int(eq.steps[i - rows.start]) <= int(single.steps)


def test_pools_side_by_side_agree_with_one_pool_and_stop_cleanly(scene, monkeypatch):
    # On one CPU device two slot pools share the rows, each in its own thread: the results are
    # those of one pool (the same steps; the pools' sizes differ, hence round-off); a caller
    # that stops early, or a failure inside a pool, leaves no thread behind; a failure reaches
    # the caller.
    import threading

    from pacjax._statics import pool as _pool

    commands = np.random.default_rng(5).uniform(0.0, 0.012, (12, 3))
    assert _pool.pool_lanes(3, None, warm_start=False) == 2
    assert _pool.pool_lanes(3, None, warm_start=True) == 1
    assert _pool.pool_lanes(1, None, warm_start=False) == 1
    threads = threading.active_count()
    two = pj.solve_batch(scene, commands, chunk_size=3)
    monkeypatch.setattr(_pool, "CPU_LANES", 1)
    one = pj.solve_batch(scene, commands, chunk_size=3)
    monkeypatch.undo()
    np.testing.assert_allclose(two.q, one.q, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(two.steps, one.steps)
    assert np.all(two.converged)

    parts = pj.iter_batch(scene, commands, chunk_size=3)
    rows, _ = next(parts)
    assert rows == slice(0, 3)
    parts.close()
    assert threading.active_count() == threads

    def broken(sc, m):
        raise RuntimeError("update failed")

    with pytest.raises(RuntimeError, match="update failed"):
        pj.solve_batch(scene, commands, chunk_size=3, params=np.zeros(12), update=broken)
    assert threading.active_count() == threads


@pytest.mark.slow  # two batch programs of the paper's robot (static and traced site)
def test_known_load_site_is_static_and_agrees_with_a_traced_site(scene):
    # A load site known before the solve is compiled in as a knot; a traced one (here under
    # jit) is integrated on its own. Both are the same physics.
    moved = eqx.tree_at(lambda s: s.loads[1].s, scene, 0.6)
    u = np.array([0.004, 0.0, 0.001])
    known = pj.solve_equilibrium(moved, u)

    @jax.jit
    def traced(site):
        return pj.solve_equilibrium(eqx.tree_at(lambda s: s.loads[1].s, scene, site), u).q

    # The two kinematics paths agree to their quadrature accuracy (~1e-9 relative).
    np.testing.assert_allclose(traced(jnp.asarray(0.6)), known.q, atol=1e-7)
    assert known.converged


def test_batch_under_a_trace_says_to_vmap_the_single_solve():
    scene = pj.presets.tentacle()
    with pytest.raises(TypeError, match=r"jax.vmap\(pj.solve_equilibrium\)"):
        jax.grad(lambda u: jnp.sum(pj.solve_batch(scene, u).q))(jnp.ones((2, 2)))


def test_only_the_first_pool_of_a_kind_runs_an_idle_round(scene, monkeypatch):
    # The idle round (no slot active) compiles the pool's round in the background; once a
    # round of the same kind has run in this process it is compiled, and the round is skipped.
    # A pool of another kind (another size) runs its own.
    from pacjax._statics import pool

    idle = []
    round_ = pool._round

    def spy(*args):
        slots, pending = args[7], args[8]
        idle.append(not len(pending[0]) and not np.any(np.asarray(slots[4]) >= 0))
        return round_(*args)

    monkeypatch.setattr(pool, "_round", spy)
    monkeypatch.setattr(pool, "_ROUNDS_RUN", type(pool._ROUNDS_RUN)())
    commands = np.random.default_rng(5).uniform(0.0, 0.01, (6, 3))
    first = pj.solve_batch(scene, commands)
    assert sum(idle) == 1
    idle.clear()
    second = pj.solve_batch(scene, commands)
    assert sum(idle) == 0 and len(idle) > 0
    np.testing.assert_array_equal(first.q, second.q)
    idle.clear()
    pj.solve_batch(scene, commands[:3])
    assert sum(idle) == 1


def test_a_rows_bits_do_not_depend_on_its_place_in_the_batch():
    # The pool ends a row at the step it tried ahead. Where that point came from a PCC/PAC
    # bending-vector move, its last bit depended on the row's slot (the two pools take rows in
    # whatever order they finish), so a batch differed from run to run and a resumed batch
    # file from the uninterrupted one; the step tried ahead near a solution is a plain sum.
    seg = pj.Segment(0.15, 0.01, 1e5, linear_density=0.05)
    tendons = [pj.Tendon(0, a, 0.008, mode="tension") for a in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)]
    scene = pj.Scene(pj.Robot([seg]), pj.PCC(), tendons=tendons, loads=(pj.Gravity(),))
    commands = np.random.default_rng(0).uniform(0.0, 3.0, (64, 3))
    first = pj.solve_batch(scene, commands, chunk_size=32, progress=False)
    order = np.random.default_rng(1).permutation(64)
    again = pj.solve_batch(scene, commands[order], chunk_size=32, progress=False)
    assert np.all(first.converged)
    for name in ("q", "residual_norm", "energy", "steps"):
        np.testing.assert_array_equal(
            np.asarray(getattr(first, name))[order], np.asarray(getattr(again, name)), name
        )
