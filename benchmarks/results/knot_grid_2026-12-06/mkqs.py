import numpy as np, pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
qs = []
for u in ([0.04]+[0]*8, [0.08]+[0]*8, [0.08,0,0,0.04,0,0,0,0,0.03], [0.12,0,0,0,0,0,0.05,0,0]):
    e = pj.solve_equilibrium(scene, np.array(u, float)); qs.append(np.asarray(e.q)); print(u, e.result if hasattr(e,'result') else '', np.asarray(e.q).round(2))
np.save("qs.npy", np.array(qs))
