"""The ARROCH simulator (the paper's SUGAR2): robots, doors, the simulated human, the pybullet
world and the virtual tablet camera. See "Simulator engine" and "Simulator world and camera" in
docs/services/sim.md."""
