"""Runs as the service sees them: a run and the results it shows, the runs listed and a run
deleted, creating a run from an ingested file with its first job, correcting its metadata, the
jobs of a run (reprocess, cancel), and the channel maps recorder files are read with.

- :mod:`~app.runs.lookup`: a run, and the job whose results it shows (404, 409 otherwise);
- :mod:`~app.runs.catalog`: runs and jobs as listed and shown (latest job, chunks done), a run deleted;
- :mod:`~app.runs.upload`: what is decided of a received upload (format, metadata, rate, refusals);
- :mod:`~app.runs.create`: a run row and its queued job from an ingested file (upload, CLI);
- :mod:`~app.runs.metadata`: a run's metadata compared with a re-upload's, corrected by PATCH;
- :mod:`~app.runs.jobs`: the settings of a new job (reprocessing) from a request, a cancel, the job lists;
- :mod:`~app.runs.channel_maps`: the channel maps per vehicle, selected at upload.
"""
