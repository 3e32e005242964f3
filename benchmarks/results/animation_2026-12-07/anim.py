import time, sys, numpy as np, jax
import pacjax as pj
from pacjax.plots import animation as A
from pacjax.io.scenefile import load_scene
scene, _, _ = load_scene("/work/main/experiments/scenes/stella2023.toml")
u = np.array([0.04] + [0.0] * 8)
start = pj.solve_equilibrium(scene, np.zeros(9))
tr = pj.simulate(scene, (0.0, 2.0), u, q0=start.q, saveat=np.linspace(0, 2.0, 41))
jax.block_until_ready(tr)
for k in range(2):
    t = time.perf_counter(); A.animate_trajectory(scene, tr, f"a{k}.gif", fps=20, title="stella2023"); print("animate", round(time.perf_counter() - t, 2), flush=True)
t = time.perf_counter(); A.plot_tip_trajectory(scene, tr, "tip.png"); print("tip plot", round(time.perf_counter() - t, 2))
