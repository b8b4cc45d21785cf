"""Places: the work list an engineer acts on (issue 25, docs/places.md).

After a run's condition rows are published, :func:`app.places.update.update_places` finds the
run's places on the speed-conditioned stiffness index and advances the line's known places
(identity, tiers, lifecycle, maintenance links), writes their observations and events and queues
the alerts of new places and tier changes. :mod:`app.places.worklist` answers the work list, its
exports and a place's history; :mod:`app.places.workflow` the engineers' status changes.
"""
