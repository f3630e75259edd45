"""The causes a pulse without a return is given (:func:`muls.ranging.returns.dropout_causes`): a pulse's dropout code
indexes :data:`DROPOUT_CAUSES`, and :data:`NO_DROPOUT` marks a pulse with a return. A module of its own, importing
nothing, so that what only names the causes (the coverage settings behind a study's ``--help``) loads no kernel."""

DROPOUT_CAUSES = ("no_hit", "blind_zone", "below_threshold", "saturated", "masked_by_backscatter", "outside_gate")
NO_DROPOUT = -1
