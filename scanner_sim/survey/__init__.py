"""The pass: its set-up (stages chosen once), the chunk loop, the hand-off from hits to the MULS physics,
georeferencing into point and dropout records, and the sinks the chunks flow into."""
