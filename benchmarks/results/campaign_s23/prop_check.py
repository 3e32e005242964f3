import json, sys
import os; ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../..")); sys.path.insert(0, ROOT + "/tests"); sys.path.insert(0, ROOT + "/benchmarks")
import numpy as np
from scene_space import build, check, PropertyFailure
from campaign import structures_of
d = json.load(open(ROOT + "/benchmarks/results/campaign_deep_s23.json"))
bad = d["not_ok"]
structures = structures_of(500, 23)
for rec in bad[int(sys.argv[1]):int(sys.argv[2])]:
    structure = structures[rec["structure_index"]]
    scene, controls = build(structure, rec["values"])
    try:
        print(structure.describe(), "->", check(scene, controls, structure.dtype))
    except PropertyFailure as err:
        print(structure.describe(), "-> PropertyFailure", err)
