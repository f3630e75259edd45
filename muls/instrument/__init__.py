"""The instrument stage: the lidar itself, before it meets any water.

Takes the paper's Table 1 values (or a user's). Gives the :class:`~.description.Instrument` (transmitter,
receiver, channels, reference, digitiser, processing: :mod:`.description`), the emitted pulse through the analog
filter (:mod:`.pulse`), the transceiver geometry and its overlap, Eq. 11 (:mod:`.overlap`), the per-channel
constants of the compiled kernels, Eqs. 12-13 (:mod:`.channels`) and the tables of the filtered pulse shape that
ranging inverts (:mod:`.shape_tables`).
"""
