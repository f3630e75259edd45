"""The world a pass surveys: the scene's meshes (seabed, rocks, cables, mines, panels, mesh files), their
materials and class labels, and the seabed's height field."""
