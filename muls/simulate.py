"""One call from what pulses meet to records and ranges: the MULS flow of Figure 2 for a batch."""

from __future__ import annotations

from .optics.optical_model import OpticalModel, PulseBatch
from .ranging.returns import Ranging, range_batch
from .receiver.digitiser import Waveforms, digitise


def simulate(model: OpticalModel, batch: PulseBatch, seed, mode: str = "windowed",
             keep_noise_free: bool = False, noise: bool = True, deciding_only: bool = False, ranging_only: bool = False,
             explain_dropouts: bool = True) -> tuple[Waveforms, Ranging]:
    """Digitise the channels of ``batch`` (Eqs. 1-13) and range it (Eq. 14).

    Parameters
    ----------
    model : OpticalModel
        One instrument in one water, with its tables.
    batch : PulseBatch
        What each of the batch's n_pulses pulses meets: echo ranges and weights, column cuts, background.
    seed : int or numpy.random.Generator
        Keys all noise; a pulse's draws depend only on (seed, pulse id, stream, sample).
    mode : {"windowed", "full"}
        Record windows around the echoes, or each pulse's whole record.
    keep_noise_free, noise : bool
        Keep the noise-free codes beside the noisy ones; draw noise at all.
    deciding_only : bool
        Synthesise only the channels that can decide a return (the ``fast`` and ``auto`` levels).
    ranging_only : bool
        Code only the samples the ranging may read: the same ranges for less work.
    explain_dropouts : bool
        Give each pulse without a return its dropout cause (False: ``ranging.dropout_cause`` is None).

    Returns
    -------
    waveforms : Waveforms
        The digitised records: CH0 reference (n_pulses, n_ref) and signal windows (n_windows, n_channels,
        n_samples) uint16 (:func:`muls.receiver.digitiser.digitise`).
    ranging : Ranging
        The returns (one row each), every peak, and a dropout cause (n_pulses,) for each pulse without a return.
    """
    echoes = model.echoes(batch)
    records = digitise(model, batch, seed, mode=mode, keep_noise_free=keep_noise_free, noise=noise, echoes=echoes,
                       deciding_only=deciding_only, ranging_only=ranging_only)
    return records, range_batch(model, batch, records, echoes, explain_dropouts)
