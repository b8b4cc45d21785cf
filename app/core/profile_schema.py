"""What a stored profile row (25 cm bins) holds beside the job's settings: the version of the engine that
made its numbers and the names of its sleeper-passage columns.

The pipeline fills them (:mod:`app.pipeline.assemble`); the readers (the API's profile answers, the places'
index keys) name them from here, without loading the processing engine (the VKF, numba, scipy.signal).
"""

#: bump when the stored numbers would change for the same input and settings
#: (3: real-signal VKF model, per-order bandwidths, sleeper harmonics, static load out of Q;
#: 4: track impacts bridged out of the sleeper columns, track_impact_mm, wheel flats;
#: 5: and sleeper_amp the roughness-corrected estimate, sleeper_amp_raw / sleeper_amp_sd beside it;
#: 6: one track impact per dip, and each impact's mask reaching the offset of its largest disturbance)
ENGINE_VERSION = "trackvkf-pipeline/6"
#: the sleeper-passage columns of a profile row: the fundamental (m/s²), its 2nd and
#: 3rd harmonics (m/s², NaN where not extracted) and their RMS (the energy indicator, m/s²)
TRACK_COLUMNS: tuple[str, ...] = ("sleeper_amp", "sleeper_2_amp", "sleeper_3_amp", "sleeper_rms")
#: the roughness columns (issue 26, :mod:`app.analysis.roughness`): the single-wheel VKF amplitude at
#: f_s as before (``sleeper_amp`` is now the best estimate: floor-corrected, or common to the two rails
#: of an axle), the 1-σ of ``sleeper_amp`` and the part of it shared along the floor window, m/s²
ROUGHNESS_COLUMNS: tuple[str, ...] = ("sleeper_amp_raw", "sleeper_amp_sd", "sleeper_amp_sd_shared")
#: the step estimate of ``sleeper_amp`` (issue 33 item 7, :func:`app.pipeline.assemble.sleeper_step`): its levels between change
#: points, m/s²; a reading beside ``sleeper_amp`` (docs/indicator.md, *Small steps where the signal is weak*)
STEP_COLUMN = "sleeper_step"
