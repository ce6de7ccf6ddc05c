"""Measurement artefacts in one step's time records, found before any physics.

    assess_step(force_N, accel_m_s2, disp_m, fs_Hz, freq_Hz=None) -> Assessment

One function decides what a step is worth, for ``bench analyze`` (which steps it uses)
and for the run report (which steps it lists): the :class:`StepQuality` it returns is
``usable``, ``flagged`` (used, with notes) or ``rejected`` (with the reason, naming the
channel).  Per channel (force, accel, disp), on the raw samples:

- **clipping**: samples piled up at the record's extreme value (a flat top at the
  range); rejects the step (the harmonics of a clipped record are wrong).
- **drop-out**: a run of identical samples (held value or zeros) the signal could not have
  made: the chance that noise and quantisation put every sample of the run on the held
  value, where the periodic fit says the signal was, is below 1e-4 per record; rejects.
  Runs cluster where a quantised signal is slow (its turning points): those are its own
  (decision record 0034).

Then, on the residual of the periodic fit (offset and every harmonic of the drive below
Nyquist, :mod:`sim.records`):

- **offset drift**: a linear + quadratic trend over the record, kept when its two
  coefficients differ from zero by more than 6 standard errors together (chi-square, 2
  degrees of freedom); removed, the step is flagged.
- **interference line**: a spectral peak of the residual (Hann window) at a frequency more
  than ``HARMONIC_GUARD`` record resolutions (fs/N) from every drive harmonic (and from
  where harmonics above Nyquist fold back, when the record has content up there), above the
  noise floor by a factor that gives a false alarm probability of 1e-4 per record and
  channel (near a folded harmonic only above what a fold can be, 10 x the largest of the
  top tenth fitted: decision record 0088); its frequency, amplitude and phase are fitted by least squares (with a decay
  rate, to tell a line from a transient), and a steady line is **removed** from the record:
  the step stays usable (flagged).  Up to ``MAX_LINES`` per channel.  A "line" the probe
  and the accelerometer see as one motion (both components above ``MOTION_Z`` standard
  errors, the accelerometer's -(2 pi f)^2 times the probe's in amplitude and phase) is a
  free vibration too slow to decay within the record, named an unsettled transient; so is
  a line on another channel at its frequency (decision record 0033).
- **unsettled transient**: a spectral peak whose fitted decay rate is positive by more
  than 6 standard errors and which loses more than 20 % of its amplitude over the record
  is a transient with its own frequency: it is **removed** like a line.  A transient the
  record cannot tell from the drive shows in the difference between consecutive periods,
  x(t + T) - x(t), where the periodic part cancels: its mean square per period falling
  (the first above the noise by more than 10 standard errors) gives the decay.
  A transient is harmless once its amplitude has fallen to ``A_tol = s sqrt(2/N)
  max(1, sigma T / 2)`` (s the noise rms, N samples, T the record length, sigma the decay
  rate): then the bias it leaves on any harmonic is below that harmonic's standard error.
  The settle cycles the plan needs are ``ceil(f ln(A_0 / A_tol) / sigma)``.  A transient
  that was not removed: when what is left after that holds at least
  ``max(MIN_PERIODS, periods / 4)`` whole periods, the first periods are dropped and the
  step is kept (flagged); otherwise the periodicity gate decides, and a rejection names
  the transient and the settle cycles it needs.

Finally the cleaned records pass the periodicity gate of :mod:`sim.records` (harmonics 1-3
and offset of each channel, first half against second, at most ``DRIFT_LIMIT`` standard
errors), and a step whose displacement residual (noise) is above ``NOISY_RESIDUAL`` of its
fundamental is flagged as noisy (used, with its noise as weight).

:func:`artefact_causes` aggregates the artefacts of many steps into ``analysis.json``
causes of ``kind: "artefact"`` (docs/analysis.md, decision record 0024).

The package, by job: :mod:`.detectors` (clipping, drop-outs, the periodic fit, trend, lines
and transients), :mod:`.cleaning` (one channel cleaned, settle cycles, free vibration),
:mod:`.decision` (:func:`assess_step`), :mod:`.sentences` (names, units, SI sizes, mains), :mod:`.quality` (the step's :class:`StepQuality`) and :mod:`.causes`
(many steps: :func:`attribute_lines`, :func:`artefact_causes`).
"""

from .causes import LINE_CLUSTER_REL, MODE_REL, REPEAT_STEPS, artefact_causes, attribute_lines
from .cleaning import ENVELOPE_Z, MOTION_TOL, MOTION_Z, TREND_Z, settle_cycles
from .decision import DRIFT_LIMIT, MIN_PERIODS, NOISY_RESIDUAL, assess_step
from .detectors import (
                     DECAY_FRACTION,
                     DECAY_Z,
                     DROPOUT_FALSE_ALARM,
                     DROPOUT_MIN_SAMPLES,
                     HARMONIC_GUARD,
                     LINE_FALSE_ALARM,
                     MAX_LINES,
                     find_clipping,
                     find_dropouts,
                     natural_run_chance,
                     quantisation_line_bound,
)
from .quality import KINDS, Artefact, Assessment, Rejection, StepQuality
from .sentences import FORMULAS, LABEL, LABELS, MAINS_HZ, UNIT, mains, mains_line, si

__all__ = ["DECAY_FRACTION", "DECAY_Z", "DRIFT_LIMIT", "DROPOUT_FALSE_ALARM", "DROPOUT_MIN_SAMPLES", "ENVELOPE_Z",
           "FORMULAS", "HARMONIC_GUARD", "KINDS", "LABEL", "LABELS", "LINE_CLUSTER_REL", "LINE_FALSE_ALARM",
           "MAINS_HZ", "MAX_LINES", "MIN_PERIODS", "MODE_REL", "MOTION_TOL", "MOTION_Z", "NOISY_RESIDUAL",
           "REPEAT_STEPS", "TREND_Z", "UNIT", "Artefact", "Assessment", "Rejection", "StepQuality", "artefact_causes",
           "assess_step", "attribute_lines", "find_clipping", "find_dropouts", "mains", "mains_line",
           "natural_run_chance", "quantisation_line_bound", "settle_cycles", "si"]
