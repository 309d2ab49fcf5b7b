"""What the robot sees: camera views of terrain, the terrain-image dataset and the terrain classifier."""
