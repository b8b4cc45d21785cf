"""The segment condition store: what a published run's 25 cm rows become, and what is read back.

The numbers are decided in :mod:`app.analysis.condition` (pure); this package puts them
into and out of the store's tables (:mod:`app.db.models.condition`):

- :mod:`~app.condition.config`: how runs become condition rows (from the settings);
- :mod:`~app.condition.writer`: a published job's segment rows, change tests and flags;
- :mod:`~app.condition.actions`: the line's recorded maintenance actions on the change tests' time axis
  (on the rails' surface or on the support);
- :mod:`~app.condition.alerts`: the alerts outbox of new flags (one delivery per webhook);
- :mod:`~app.condition.readers`: lines, heat maps, segment histories, flags, the feed, an extent against its
  surroundings (the one rule: :func:`~app.condition.readers.extent_readings`);
- :mod:`~app.condition.answers`: the answers of the ``/condition`` endpoints;
- :mod:`~app.condition.fleet`: a generated fleet history written like processed runs;
- :mod:`~app.condition.index`: which index the store keeps.
"""
