"""Where to act, in one home (issue 25, docs/places.md): the places an engineer acts on.

The numerics are pure (:mod:`app.analysis.condition`: ``run_places``, ``lifecycle``, ``tiers``,
``section_class``, ``extent_level`` …); this package reads and writes them:

- :mod:`~app.places.config`: the places' settings as the numerics' parameter objects;
- :mod:`~app.places.index`: the index places are graded on, ``ln(A / A_ref(class, v))`` of a run
  and its history from the condition store's 10 m rows (its method version);
- :mod:`~app.places.update`: a published run's places found and the line's places advanced by it;
- :mod:`~app.places.store`: the places' rows written back (state, observations, events, action links,
  the service's own status changes);
- :mod:`~app.places.followup`: the publish step's places follow-up (once per run, in line order);
- :mod:`~app.places.alerts`: the alerts of new places, tier changes and places back;
- :mod:`~app.places.worklist`, :mod:`~app.places.answers`: the work list, its exports, a place's history;
- :mod:`~app.places.workflow`: the engineers' status changes;
- :mod:`~app.places.sections`: the section classes A … E of a line from the same index;
- :mod:`~app.places.effect`: what a maintenance action did, its extent read against its surroundings.
"""
