"""Reference data (subsidence, maintenance, superstructure): imports and deletes by engineers,
audited, and the windowed lists the API answers (:mod:`~app.reference.service`). Files are parsed
by :mod:`app.io.reference`; rows are stored and queried by :mod:`app.db.reference_crud`."""
