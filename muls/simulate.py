"""One call from what pulses meet to records and ranges: the MULS flow of Figure 2 for a batch."""

from __future__ import annotations

from .detection import Records, digitise
from .ranging import Ranging, range_batch
from .waveform import OpticalModel, PulseBatch


def simulate(model: OpticalModel, batch: PulseBatch, seed, mode: str = "windowed",
             keep_noise_free: bool = False, noise: bool = True) -> tuple[Records, Ranging]:
    """Digitise every channel of ``batch`` (Eqs. 1-13) and range it (Eq. 14); ``seed`` keys all noise."""
    echoes = model.echoes(batch)
    records = digitise(model, batch, seed, mode=mode, keep_noise_free=keep_noise_free, noise=noise, echoes=echoes)
    return records, range_batch(model, batch, records, echoes)
