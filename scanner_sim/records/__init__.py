"""The shared records, below every stage that makes or reads them: what a pass produces per point and per dropout.

Takes nothing from the other stages (only muls's dropout causes). Gives :class:`~.point_records.PointRecords` and
:class:`~.point_records.DropoutRecords`, frozen struct-of-arrays with each field's unit and LAS column
(:mod:`.point_records`), which the survey fills and io, metrics and render read.
"""
