"""The receiver stage: optical power to digitised records.

Takes an :class:`~muls.optics.optical_model.OpticalModel` and a batch of pulses. Gives the digitised records,
codes per channel and sample with the CH0 reference (:mod:`.digitiser`: beam splitter and gains, gate, dark and
shot noise, sampling, quantisation, clipping), where the records are synthesised (:mod:`.record_windows`: the
whole record or windows around the echoes), a window's codes for every sample or only those the
peak search may read (:mod:`.channel_codes`) and which channels of a window can decide a return
(:mod:`.deciding_channels`).
"""
