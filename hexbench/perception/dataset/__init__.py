"""The terrain-image dataset (paper 3.1): robot-camera views of rough ground, slopes and stairs.

  views.py     what one image is (terrain, level, pose, ground colour) and how it is rendered
  build.py     `hexbench dataset build terrain-images`: the ImageFolder tree, split by terrain seed
  archive.py   deterministic .tar.gz packing and safe extraction
  registry.py  `hexbench dataset download`: the pooch registry in datasets/registry.toml
"""

DATASET_NAME = "terrain-images"
