"""One call from what pulses meet to records and ranges: the MULS flow of Figure 2 for a batch."""

from __future__ import annotations

from .optics.optical_model import OpticalModel, PulseBatch
from .ranging.returns import Ranging, range_batch
from .receiver.digitiser import Waveforms, digitise


def simulate(model: OpticalModel, batch: PulseBatch, seed, mode: str = "windowed",
             keep_noise_free: bool = False, noise: bool = True, deciding_only: bool = False, ranging_only: bool = False
             ) -> tuple[Waveforms, Ranging]:
    """Digitise the channels of ``batch`` (Eqs. 1-13) and range it (Eq. 14); ``seed`` keys all noise.
    ``deciding_only``: only the channels that can decide a return; ``ranging_only``: only the samples the ranging may
    read, the same ranges for less work (:func:`muls.receiver.digitiser.digitise`)."""
    echoes = model.echoes(batch)
    records = digitise(model, batch, seed, mode=mode, keep_noise_free=keep_noise_free, noise=noise, echoes=echoes,
                       deciding_only=deciding_only, ranging_only=ranging_only)
    return records, range_batch(model, batch, records, echoes)
