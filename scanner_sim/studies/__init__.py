"""Studies made of many passes or runs: the coverage study, speed against accuracy (trade-off) and its
accuracy metrics, and the ray-cast overlap against Eq. 11."""
