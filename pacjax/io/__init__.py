"""Files: scenes in TOML (:mod:`pacjax.io.scenefile`) and motion capture in the documented CSV
or OptiTrack Motive exports (:mod:`pacjax.io.mocapfile`)."""

from .mocapfile import load_mocap as load_mocap
from .mocapfile import motive_dataset as motive_dataset
from .mocapfile import read_motive_csv as read_motive_csv
from .mocapfile import save_mocap as save_mocap
from .scenefile import load_scene as load_scene
from .scenefile import save_scene as save_scene
from .scenefile import scene_from_toml as scene_from_toml
from .scenefile import scene_to_toml as scene_to_toml
