"""Runs as the service sees them: a run and the results it shows, creating a run from an ingested
file with its first job, correcting its metadata, and the settings of a reprocessing job.

- :mod:`~app.runs.lookup`: a run, and the job whose results it shows (404, 409 otherwise);
- :mod:`~app.runs.create`: a run row and its queued job from an ingested file (upload, CLI);
- :mod:`~app.runs.metadata`: a run's metadata compared with a re-upload's, corrected by PATCH;
- :mod:`~app.runs.jobs`: the settings of a new job (reprocessing) from a request.
"""
