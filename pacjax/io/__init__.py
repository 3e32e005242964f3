"""Files: scenes in TOML (:mod:`pacjax.io.scenefile`) and motion capture in the documented CSV
(:mod:`pacjax.io.mocapfile`) or OptiTrack Motive exports (:mod:`pacjax.io.motive`)."""

from .mocapfile import load_mocap as load_mocap
from .mocapfile import save_mocap as save_mocap
from .motive import motive_dataset as motive_dataset
from .motive import read_motive_csv as read_motive_csv
from .scenefile import load_scene as load_scene
from .scenefile import save_scene as save_scene
from .scenefile import scene_from_toml as scene_from_toml
from .scenefile import scene_to_toml as scene_to_toml
