"""The ranging stage: digitised records to ranges, as the instrument's processing does it (Eq. 14).

Takes the records of :mod:`muls.receiver` and the optical model that made them. Gives the peaks of every channel
with sub-sample timing (:mod:`.peaks`), the echo behind each peak (:mod:`.peak_echoes`), in ranging's order
(:mod:`.peak_order`), and the returns, one channel chosen per return, with a dropout cause for every pulse without
one (:mod:`.returns`; the causes' names in :mod:`.causes`).
"""
