"""Measures of a pass's points against the truth: seabed coverage and its gaps, swath-to-swath consistency."""
