"""The optics stage: an instrument in a water, from emitted energy to optical power at the detector.

Takes an :class:`~muls.instrument.description.Instrument`, a :class:`~muls.water.properties.Water` and what each
pulse meets (echo ranges and weights, where the column is cut). Gives the power terms of the lidar equation,
Eqs. 3, 4, 7-10 (:mod:`.radiometry`), with the Monte Carlo's multiple-scattering tables per water and receiver
(:mod:`muls.montecarlo.scattering_tables`, from the stage below) applied, an echo spread in time by them
(:mod:`.echo_spread`) and the
:class:`~.optical_model.OpticalModel` with its :class:`~.optical_model.PulseBatch` and echoes
(:mod:`.optical_model`): the noise-free optical waveform of a batch, in watts, whose values at a sample are
compiled in :mod:`.sample_kernels`.
"""
