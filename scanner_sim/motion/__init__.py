"""How the instrument moves: the platform's trajectory (true and estimated poses), the mirror scanner that
turns a pose into beam and receiver rays, and the checks of the track against the scene."""
