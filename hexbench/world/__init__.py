"""The world: the robot, its CPG, terrain, the simulation, rewards, the episode rules and the Gymnasium env composed from them."""
